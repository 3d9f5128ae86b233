"""A Ctrl-C that lands inside MuJoCo's warning callback (called from C during a compile) must not abort the
process: the callback keeps it and it is raised once the compile has returned to Python (issue 10 item 3)."""

from __future__ import annotations

import pytest

from dgz_cli.spec.urdfxml import captured_mujoco_warnings


class _Interrupting:
    def __str__(self) -> str:
        raise KeyboardInterrupt


def test_ctrl_c_in_the_warning_callback_is_deferred_to_python():
    import mujoco

    after = []
    with pytest.raises(KeyboardInterrupt):
        with captured_mujoco_warnings() as messages:
            callback = mujoco.get_mju_user_warning()
            callback(_Interrupting())          # as MuJoCo would call it, with the interrupt landing inside
            callback("a normal warning")       # the callback keeps working
            after.append(list(messages))
    assert after == [["a normal warning"]]     # the interrupt did not escape the callback itself
    assert mujoco.get_mju_user_warning() is not callback  # the previous handler is back
