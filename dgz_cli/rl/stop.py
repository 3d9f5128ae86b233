"""A stop request that a signal handler sets and a training loop honours at its next step boundary.

Raising KeyboardInterrupt from the handler itself would interrupt whatever the main thread is doing, and it
usually waits on the physics pool's futures: interrupted while re-acquiring a ``threading.Condition``, the wait
turns the KeyboardInterrupt into ``RuntimeError: cannot release un-acquired lock`` and the run exits 1 without
saving the iteration in progress (seen once in CI). So the handler only records the request, and
:meth:`StopRequest.check`, called by the loops between env steps and mini-batches, raises KeyboardInterrupt from
plain code, where the loops' save-on-interrupt handling takes over.
"""

from __future__ import annotations


class StopRequest:
    def __init__(self) -> None:
        self.requested = False

    def request(self) -> None:
        self.requested = True

    def check(self) -> None:
        """Raise KeyboardInterrupt if a stop was requested."""
        if self.requested:
            raise KeyboardInterrupt
