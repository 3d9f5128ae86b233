"""Functional partitioning of finger chains into semantic nodes (Supp. S1-A).

1. Consecutive joints whose anchors coincide (< 2 mm at the rest pose) form one articulation
   (a universal joint such as Shadow's MCP).
2. Every FLEX articulation starts a node (a new phalanx). An articulation without FLEX joins
   the node before it when that node has room and no joint of the same primitive (LEAP's MCP
   abduction behind its flexion); otherwise it opens a node that the next FLEX articulation
   joins when the result still holds ≤ 3 joints (Allegro's finger-root twist + MCP flexion).
3. Types from the fingertip inwards: distal, middle, proximal, metacarpal; one node → proximal.
   Every finger ends in a joint-less fingertip node; every finger's first node hangs off the
   wrist node, which holds the wrist joints and any joint that moves several fingers.
"""

from __future__ import annotations

import numpy as np

from dgz_cli.onboard.compile import Poser
from dgz_cli.spec.errors import OnboardError

TYPES_BY_COUNT = {1: ["proximal"], 2: ["proximal", "distal"], 3: ["proximal", "middle", "distal"],
                  4: ["metacarpal", "proximal", "middle", "distal"]}
COINCIDENT = 0.002  # m


def group_chain(chain: tuple[str, ...], primitive: dict[str, str], poser: Poser, where: str) -> list[list[str]]:
    poser.pose(poser.rest())
    arts: list[list[str]] = []
    for j in chain:
        if arts and np.linalg.norm(poser.joint_anchor(j) - poser.joint_anchor(arts[-1][-1])) < COINCIDENT:
            arts[-1].append(j)
        else:
            arts.append([j])

    def prims(group: list[str]) -> set[str]:
        return {primitive[j] for j in group}

    nodes: list[list[str]] = []
    for art in arts:
        has_flex = "FLEX" in prims(art)
        last = nodes[-1] if nodes else None
        if has_flex:
            if last is not None and "FLEX" not in prims(last) and len(last) + len(art) <= 3 \
                    and not (prims(last) & prims(art)):
                last.extend(art)
            else:
                nodes.append(list(art))
        elif last is not None and len(last) + len(art) <= 3 and not (prims(last) & prims(art)):
            last.extend(art)
        else:
            nodes.append(list(art))
    for n in nodes:
        if len(n) > 3:
            raise OnboardError(f"{where}: joints {', '.join(n)} form one articulation of {len(n)} joints (max 3)",
                               "split them with node overrides in an --overrides file")
    if len(nodes) > 4:
        raise OnboardError(f"{where}: finger chain {chain[0]}…{chain[-1]} has {len(nodes)} phalanx nodes (max 4)",
                           "check the primitives of its joints (`dgz onboard --json`) and override the wrong ones")
    return nodes
