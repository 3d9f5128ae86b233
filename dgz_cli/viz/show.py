"""Draw a HandSpec's morphology-aligned graph over the URDF's kinematic skeleton.

Two orthographic views in the palm frame (x = f finger axis, y = l lateral, z = n palm normal):
a front view of the palm (l horizontal, f up, looking along −n) and a side view (n horizontal,
f up). matplotlib and MuJoCo are imported inside the functions so importing this module is cheap.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from dgz_cli.spec.models import PRIMITIVES, HandSpec

NODE_COLORS = {
    "wrist": "#404040",
    "metacarpal": "#8c564b",
    "proximal": "#ff7f0e",
    "middle": "#bcbd22",
    "distal": "#17becf",
    "fingertip": "#e377c2",
}
PRIMITIVE_COLORS = {"FLEX": "#d62728", "ABD": "#2ca02c", "ROT": "#1f77b4"}
ARROW_LEN = 0.02  # m, joint-axis arrows
FRAME_LEN = 0.03  # m, palm-frame axes
SCALE = 100.0  # plot in cm
_MASK_LETTERS = ("F", "A", "R")


def graph_table_rows(spec: HandSpec) -> list[tuple[str, str, str, str, str, str]]:
    """One row per node: (id, finger, type, parent or "—", joints, mask).

    ``joints`` lists each member joint followed by its primitive and sign from M_h
    (``"joint_1.0 FLEX+"``); a mimic joint is shown as ``"j mimic(source)"``. ``mask`` is the
    activation mask as ``F A R`` letters with ``·`` for 0 (e.g. ``"F·R"``).
    """
    rows_by_joint = {r.joint: r for r in spec.joints}
    mimic_by_joint = {m.joint: m for m in spec.mimic}
    out = []
    for node in spec.nodes:
        parts = []
        for j in node.joints:
            if j in rows_by_joint:
                r = rows_by_joint[j]
                parts.append(f"{j} {r.primitive.value}{'+' if r.sign > 0 else '-'}")
            elif j in mimic_by_joint:
                parts.append(f"{j} mimic({mimic_by_joint[j].source})")
            else:
                parts.append(j)
        mask = spec.activation_mask.get(node.id, [0, 0, 0])
        mask_s = "".join(letter if bit else "·" for letter, bit in zip(_MASK_LETTERS, mask))
        out.append((node.id, node.finger, node.type, node.parent if node.parent is not None else "—",
                    ", ".join(parts), mask_s))
    return out


def _subtree_links(kin, root: str) -> set[str]:
    links, stack = {root}, [root]
    while stack:
        for j in kin.children(stack.pop()):
            if j.child not in links:
                links.add(j.child)
                stack.append(j.child)
    return links


def render_png(spec: HandSpec, urdf_path: Path, out: Path) -> None:
    """Render the front and side views of ``spec``'s graph over ``urdf_path``'s skeleton to ``out`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    from dgz_cli.onboard.compile import Poser, compile_model
    from dgz_cli.onboard.urdf import load_kinematics

    kin = load_kinematics(Path(urdf_path), spec.provenance.xacro_args)
    poser = Poser(kin, compile_model(kin))
    poser.pose(poser.rest())

    palm = spec.palm
    r_palm = poser.link_rot(palm.link)
    origin = poser.link_pos(palm.link) + r_palm @ np.asarray(palm.center, dtype=float)
    basis = np.stack([r_palm @ np.asarray(v, dtype=float) for v in (palm.finger_axis, palm.lateral, palm.normal)])

    def to_palm(p_world: np.ndarray) -> np.ndarray:  # world point → palm-frame (f, l, n), cm
        return basis @ (np.asarray(p_world) - origin) * SCALE

    def dir_palm(v_world: np.ndarray) -> np.ndarray:  # world direction → palm-frame (f, l, n)
        return basis @ np.asarray(v_world)

    # ---- geometry in the palm frame --------------------------------------------------------------
    hand_links = _subtree_links(kin, palm.link)
    skeleton = []  # (p_parent, p_child, in_hand)
    for j in kin.joints.values():
        skeleton.append((to_palm(poser.link_pos(j.parent)), to_palm(poser.link_pos(j.child)),
                         j.child in hand_links))
    anchors = {n.id: to_palm(poser.link_pos(n.anchor_link, np.asarray(n.anchor_point, dtype=float)))
               for n in spec.nodes}
    arrows = []  # (start, direction (unit, palm frame), primitive)
    for row in spec.joints:
        if row.node not in anchors:
            continue
        arrows.append((anchors[row.node], dir_palm(poser.joint_axis(row.joint)) * row.sign, row.primitive.value))

    # view index → (horizontal, vertical, toward-viewer) palm coordinates, f=0 l=1 n=2
    views = [
        ("front view (palm side, looking along −n)", 1, 0, 2, "l (cm)"),
        ("side view (looking along −l)", 2, 0, 1, "n (cm)"),
    ]

    fig = Figure(figsize=(12, 7), dpi=110)
    axes = fig.subplots(1, 2)
    n_nodes, n_act = len(spec.nodes), len(spec.joints)
    fig.suptitle(f"{spec.name}: {n_nodes} nodes, {n_act} actuated joints ({palm.side} hand)", fontsize=14)

    # extent from the hand itself (an arm in the URDF would otherwise shrink the hand to a dot)
    pts = [anchors[k] for k in anchors] + [p for a, b, inside in skeleton if inside for p in (a, b)]
    pts += [s + d * ARROW_LEN * SCALE for s, d, _ in arrows] + [np.zeros(3)]
    pts = np.array(pts)

    for ax, (title, hi, vi, ti, xlabel) in zip(axes, views):
        # kinematic skeleton
        for a, b, _ in skeleton:
            ax.plot([a[hi], b[hi]], [a[vi], b[vi]], color="#9a9a9a", lw=0.8, zorder=1, solid_capstyle="round")
        # graph edges node → parent
        for n in spec.nodes:
            if n.parent is not None and n.parent in anchors:
                a, b = anchors[n.id], anchors[n.parent]
                ax.plot([a[hi], b[hi]], [a[vi], b[vi]], color="black", lw=2.2, zorder=2)
        # joint axes × sign
        for s, d, prim in arrows:
            _axis_arrow(ax, s, d * ARROW_LEN * SCALE, hi, vi, ti, PRIMITIVE_COLORS[prim], lw=1.6, zorder=4)
        # nodes
        for n in spec.nodes:
            p = anchors[n.id]
            ax.scatter([p[hi]], [p[vi]], s=46, color=NODE_COLORS[n.type], edgecolors="black", linewidths=0.6,
                       zorder=5)
            ax.annotate(n.id, (p[hi], p[vi]), xytext=(4, 3), textcoords="offset points", fontsize=6.5,
                        color="#202020", zorder=6,
                        bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.6))
        # palm frame axes f and n at the origin
        for k, label in ((0, "f"), (2, "n")):
            e = np.zeros(3)
            e[k] = FRAME_LEN * SCALE
            _axis_arrow(ax, np.zeros(3), e, hi, vi, ti, "#6a3d9a", lw=1.4, zorder=3, label=label, dashed=True)

        span = np.ptp(pts[:, [hi, vi]], axis=0).max()
        pad = 0.08 * span + 0.5
        ax.set_xlim(pts[:, hi].min() - pad, pts[:, hi].max() + pad)
        ax.set_ylim(pts[:, vi].min() - pad, pts[:, vi].max() + pad)
        if hi == 1:
            # looking along −n with f up, +l points to the viewer's left (l = n × f)
            ax.invert_xaxis()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(title, fontsize=11)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("f (cm)")
        ax.grid(True, lw=0.3, alpha=0.5)
        ax.tick_params(labelsize=8)

    handles = [Line2D([], [], color="#9a9a9a", lw=0.8, label="URDF skeleton"),
               Line2D([], [], color="black", lw=2.2, label="graph edge")]
    handles += [Line2D([], [], ls="none", marker="o", ms=7, mfc=c, mec="black", label=t)
                for t, c in NODE_COLORS.items()]
    handles += [Line2D([], [], color=PRIMITIVE_COLORS[p], lw=1.8, label=f"{p} axis × sign") for p in PRIMITIVES]
    handles += [Line2D([], [], color="#6a3d9a", lw=1.4, ls="--", label="palm frame f, n"),
                Line2D([], [], ls="none", marker="$\\odot$", ms=9, color="#555555", label="axis toward viewer"),
                Line2D([], [], ls="none", marker="$\\otimes$", ms=9, color="#555555", label="axis away from viewer")]
    fig.legend(handles=handles, loc="lower center", ncol=8, fontsize=8, frameon=False)
    fig.subplots_adjust(left=0.06, right=0.98, top=0.9, bottom=0.14, wspace=0.15)

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp.png", dir=out.parent)
    os.close(fd)
    try:
        fig.savefig(tmp, format="png", dpi=110)
        os.replace(tmp, out)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _axis_arrow(ax, start, vec, hi, vi, ti, color, lw, zorder, label=None, dashed=False):
    """Arrow ``start → start + vec`` projected on (hi, vi); ⊙/⊗ when it points mostly along the view."""
    dx, dy = vec[hi], vec[vi]
    length = float(np.linalg.norm(vec))
    x0, y0 = start[hi], start[vi]
    if length == 0:
        return
    if np.hypot(dx, dy) < 0.25 * length:
        # ti is toward the viewer in both views (front: +n; side: the view looks along −l)
        marker = "$\\odot$" if vec[ti] > 0 else "$\\otimes$"
        ax.plot([x0], [y0], ls="none", marker=marker, ms=11, color=color, zorder=zorder)
        if label:
            ax.annotate(label, (x0, y0), xytext=(-10, -10), textcoords="offset points", fontsize=10,
                        color=color, fontweight="bold", zorder=zorder)
        return
    ax.annotate("", xy=(x0 + dx, y0 + dy), xytext=(x0, y0), zorder=zorder,
                arrowprops=dict(arrowstyle="-|>", color=color, lw=lw, mutation_scale=9, shrinkA=0, shrinkB=0,
                                ls="--" if dashed else "-"))
    if label:
        ax.annotate(label, (x0 + dx, y0 + dy), xytext=(3, 3), textcoords="offset points", fontsize=10,
                    color=color, fontweight="bold", zorder=zorder)
