"""Compare each picked residual (a line of ``tools/pick_pair_residuals.py``) with a policy's success rate on the
same (hand, object) pair in a ``dgz eval --json`` file, print one row per pair and the means, and optionally keep
only the lines whose held-out rate beats the policy's (issue 11, rung E54: demonstrations only where they are
better than the checkpoint they are cloned into).

`python3 tools/picks_beating.py PICKS.jsonl EVAL.json [OUT.jsonl]` (no package imports; OUT is written only if
given)."""
import json
import sys
from pathlib import Path


def main(picks: str, eval_json: str, out: str | None) -> None:
    hands = json.loads(Path(eval_json).read_text())["hands"]
    rows = [json.loads(line) for line in Path(picks).read_text().splitlines() if line.strip()]
    rates = [hands[r["hand"]]["objects"][r["object"]]["success_rate"] for r in rows]
    for r, policy in zip(rows, rates):
        print(f"{r['hand']:10s} {r['object']:24s} picked {r['heldout_best']:.2f} prior {r['heldout_prior']:.2f} "
              f"policy {policy:.2f}")
    kept = [r for r, policy in zip(rows, rates) if r["heldout_best"] > policy]
    mean = lambda key: sum(r[key] for r in rows) / len(rows)
    print(f"mean picked {mean('heldout_best'):.3f} prior {mean('heldout_prior'):.3f} policy "
          f"{sum(rates) / len(rates):.3f}; picked > policy on {len(kept)} of {len(rows)}")
    if out:
        lines = "".join(json.dumps(r) + "\n" for r in kept)
        tmp = Path(out + ".tmp")
        tmp.write_text(lines)
        tmp.replace(out)
        print(f"wrote {len(kept)} lines to {out}")


if __name__ == "__main__":
    if len(sys.argv) not in (3, 4):
        sys.exit("usage: python3 tools/picks_beating.py PICKS.jsonl EVAL.json [OUT.jsonl]")
    main(sys.argv[1], sys.argv[2], sys.argv[3] if len(sys.argv) == 4 else None)
