"""Rollout success of training runs in 5-iteration windows, to compare learning curves at equal transitions.

Each window is episode-weighted (Σ success_rate × episodes / Σ episodes over its iterations; an iteration in which
no episode ended, such as the first after a resume, adds nothing). Windows start at iteration 2. Also prints the
last iteration and the sum of ``wall_s``.

    .venv/bin/python tools/curve_windows.py docs/results/e13_checkpoint/history.csv runs/e29/history.csv
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

WINDOW = 5
FIRST_ITERATION = 2


def windows(history_csv: Path) -> tuple[int, float, list[float]]:
    """(last iteration, Σ wall_s, episode-weighted success per window) of one run's history.csv."""
    with history_csv.open(newline="") as handle:
        rows = {int(row["iteration"]): row for row in csv.DictReader(handle)}
    last = max(rows)
    wall = sum(float(row["wall_s"]) for row in rows.values())
    rates = []
    for start in range(FIRST_ITERATION, last + 1, WINDOW):
        successes = episodes = 0.0
        for iteration in range(start, min(start + WINDOW, last + 1)):
            row = rows.get(iteration)
            if row is not None and row["success_rate"]:
                successes += float(row["success_rate"]) * float(row["episodes"])
                episodes += float(row["episodes"])
        if episodes:
            rates.append(successes / episodes)
    return last, wall, rates


def main(paths: list[str]) -> None:
    for path in paths:
        last, wall, rates = windows(Path(path))
        print(f"{path}: iterations 1-{last}, {wall:.0f} s; " + " ".join(f"{r:.3f}" for r in rates))


if __name__ == "__main__":
    if len(sys.argv) < 2:
        sys.exit("usage: curve_windows.py HISTORY_CSV [HISTORY_CSV ...]")
    main(sys.argv[1:])
