"""Kinematic structure of a hand: palm link, wrist joints, finger chains.

The palm is the link where the movable joints first branch into several chains (fixed joints
are transparent). Movable joints between the root and the palm belong to the wrist; joints on
a segment below the palm that carries several fingers (a cupping palm joint) also belong to the
wrist node, because they move more than one finger.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dgz_cli.onboard.compile import Poser
from dgz_cli.onboard.urdf import Joint, Kinematics
from dgz_cli.spec.errors import OnboardError


@dataclass(frozen=True)
class Chain:
    """One finger: its movable joints from the palm outwards and its fingertip point."""

    joints: tuple[str, ...]
    tip_link: str
    tip_point: np.ndarray  # in tip_link's frame


@dataclass(frozen=True)
class Structure:
    palm_link: str
    palm_group: tuple[str, ...]  # links rigidly attached to the palm
    wrist_joints: tuple[str, ...]  # movable joints between root and palm (ordered root → palm)
    excluded_joints: tuple[str, ...]  # movable joints above an explicitly chosen palm (an arm)
    shared_joints: tuple[str, ...]  # movable joints below the palm that carry several fingers
    chains: tuple[Chain, ...]


def movable_frontier(kin: Kinematics, link: str) -> list[Joint]:
    """Movable joints reachable from ``link`` through fixed joints only (document order)."""
    out, stack = [], [link]
    while stack:
        for j in kin.children(stack.pop()):
            if j.movable:
                out.append(j)
            else:
                stack.append(j.child)
    order = list(kin.joints)
    return sorted(out, key=lambda j: order.index(j.name))


def rigid_group(kin: Kinematics, link: str) -> list[str]:
    """``link`` plus every link connected to it by fixed joints (up and down)."""
    group, stack = {link}, [link]
    while stack:
        cur = stack.pop()
        nbrs = [j.child for j in kin.children(cur) if not j.movable]
        pj = kin.parent_joint(cur)
        if pj is not None and not pj.movable:
            nbrs.append(pj.parent)
        for n in nbrs:
            if n not in group:
                group.add(n)
                stack.append(n)
    return [l for l in kin.links if l in group]


def _ancestors(kin: Kinematics, link: str) -> list[str]:
    out = [link]
    while (pj := kin.parent_joint(out[-1])) is not None:
        out.append(pj.parent)
    return out


def find_palm(kin: Kinematics, palm_link: str | None) -> tuple[str, list[str], list[str]]:
    """Return (palm link, wrist joints, excluded joints)."""
    if palm_link is not None:
        if palm_link not in kin.links:
            close = [l for l in kin.links if palm_link.lower() in l.lower()][:3]
            raise OnboardError(f"{kin.source}: --palm-link '{palm_link}' is not a link of this URDF",
                               f"choose one of the links{': ' + ', '.join(close) if close else ''} (`dgz show` lists them)")
        above = [kin.parent_joint(l) for l in _ancestors(kin, palm_link)[:-1]]
        excluded = [j.name for j in reversed(above) if j is not None and j.movable]
        return palm_link, [], excluded
    link, wrist = kin.root, []
    while True:
        frontier = movable_frontier(kin, link)
        if len(frontier) != 1:
            break
        wrist.append(frontier[0].name)
        link = frontier[0].child
    frontier = movable_frontier(kin, link)
    if len(wrist) > 3:
        raise OnboardError(f"{kin.source}: {len(wrist)} movable joints lie between the root and the first branching "
                           f"(this looks like an arm+hand URDF)", "pass --palm-link NAME to say where the hand starts")
    if len(frontier) < 2:
        raise OnboardError(f"{kin.source}: the movable joints never branch into two or more fingers",
                           "pass --palm-link NAME for a single-chain gripper")
    # The palm is the deepest link that is an ancestor of every branch's parent link.
    paths = [_ancestors(kin, j.parent)[::-1] for j in frontier]
    palm = paths[0][0]
    for i in range(min(len(p) for p in paths)):
        if all(p[i] == paths[0][i] for p in paths):
            palm = paths[0][i]
    return palm, wrist, []


def analyse(kin: Kinematics, poser: Poser, palm_link: str | None = None) -> Structure:
    palm, wrist, excluded = find_palm(kin, palm_link)
    shared: list[str] = []
    chains: list[list[str]] = []

    def walk(link: str, prefix: list[str]) -> None:
        frontier = movable_frontier(kin, link)
        if not frontier:
            if prefix:
                chains.append(prefix)
        elif len(frontier) == 1:
            walk(frontier[0].child, prefix + [frontier[0].name])
        else:
            shared.extend(prefix)
            for j in frontier:
                walk(j.child, [j.name])

    for j in movable_frontier(kin, palm):
        walk(j.child, [j.name])
    if len(shared) + len(wrist) > 3:
        raise OnboardError(f"{kin.source}: the wrist node would hold {len(shared) + len(wrist)} joints "
                           f"({', '.join(wrist + shared)}); a node holds at most 3",
                           "pass --palm-link NAME closer to the fingers")
    poser.pose(poser.rest())
    out = []
    for joints in chains:
        last = kin.joints[joints[-1]]
        group = rigid_group(kin, last.child)
        anchor = poser.joint_anchor(last.name)
        cands = np.vstack([np.reshape([poser.link_pos(l) for l in group], (-1, 3)),
                           np.reshape(poser.geom_points(group), (-1, 3))])
        d = cands - anchor
        tip = cands[int(np.argmax(np.sqrt(np.einsum("ij,ij->i", d, d))))]  # the first farthest, as max() picked
        local = poser.link_rot(last.child).T @ (tip - poser.link_pos(last.child))
        out.append(Chain(tuple(joints), last.child, np.round(local, 6)))
    return Structure(palm, tuple(rigid_group(kin, palm)), tuple(wrist), tuple(excluded), tuple(shared), tuple(out))
