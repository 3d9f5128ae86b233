"""Draw a HandSpec's morphology-aligned graph over the URDF's kinematic skeleton.

Two orthographic views in the palm frame (x = f finger axis, y = l lateral, z = n palm normal):
a front view of the palm (l horizontal, f up, looking along −n) and a side view (n horizontal,
f up). matplotlib and MuJoCo are imported inside the functions so importing this module is cheap.
"""

from __future__ import annotations

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
FRAME_COLOR = "#6a3d9a"
LABEL_SIZE = 6.5  # pt
LABEL_OFFSET = 6.0  # pt, node centre → label (more around ⊙/⊗ symbols)
LABEL_MERGE = 0.03  # nodes closer than this fraction of the view's extent share one label
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


def render_png(spec: HandSpec, kin, poser, out: Path) -> None:
    """Render the front and side views of ``spec``'s graph over its URDF's skeleton to ``out`` (PNG).

    ``kin``: the URDF's kinematic tree (``joints`` with ``parent``/``child``, ``children(link)``) and ``poser``
    its posable compiled model (``rest()``, ``pose(q)``, ``link_pos``, ``link_rot``, ``joint_axis``), as
    onboarding builds them (:mod:`dgz_cli.onboard`); the caller composes them, so viz stays a leaf layer."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

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
    skeleton = []  # (p_parent, p_child, in_hand): an arm's segments are drawn but do not set the extent
    for j in kin.joints.values():
        skeleton.append((to_palm(poser.link_pos(j.parent)), to_palm(poser.link_pos(j.child)),
                         j.parent in hand_links))
    anchors = {n.id: to_palm(poser.link_pos(n.anchor_link, np.asarray(n.anchor_point, dtype=float)))
               for n in spec.nodes}
    arrows, arrow_nodes = [], []  # (start, direction (unit, palm frame), primitive), node id
    for row in spec.joints:
        if row.node not in anchors:
            continue
        arrows.append((anchors[row.node], dir_palm(poser.joint_axis(row.joint)) * row.sign, row.primitive.value))
        arrow_nodes.append(row.node)

    # view index → (horizontal, vertical, toward-viewer) palm coordinates, f=0 l=1 n=2
    views = [
        ("front view (palm side, looking along −n)", 1, 0, 2, "l (cm)"),
        ("side view (looking along −l)", 2, 0, 1, "n (cm)"),
    ]

    fig = Figure(figsize=(12, 7), dpi=110)
    axes = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.06, right=0.98, top=0.9, bottom=0.14, wspace=0.15)
    n_nodes, n_act = len(spec.nodes), len(spec.joints)
    fig.suptitle(f"{spec.name}: {n_nodes} nodes, {n_act} actuated joints ({palm.side} hand)", fontsize=14,
                 parse_math=False)  # names come from an input file: never mathtext

    # extent from the hand itself (an arm in the URDF would otherwise shrink the hand to a dot)
    pts = [anchors[k] for k in anchors] + [p for a, b, inside in skeleton if inside for p in (a, b)]
    pts += [s + d * ARROW_LEN * SCALE for s, d, _ in arrows] + [np.zeros(3)]
    pts = np.array(pts)

    for ax, (title, hi, vi, ti, xlabel) in zip(axes, views):
        # looking along −n with f up, +l points to the viewer's left (l = n × f): the front view's
        # horizontal axis is inverted. ``screen`` maps palm coordinates to (right, up) in cm.
        flip = -1.0 if hi == 1 else 1.0

        def screen(v: np.ndarray, flip=flip, hi=hi, vi=vi) -> np.ndarray:
            return np.array([flip * v[hi], v[vi]])

        # equal aspect: grow the shorter range to the axes box's proportions
        span = max(float(np.ptp(pts[:, [hi, vi]], axis=0).max()), 1.0)
        pad = 0.08 * span + 0.5
        (x0, x1), (y0, y1) = ((pts[:, k].min() - pad, pts[:, k].max() + pad) for k in (hi, vi))
        box = ax.get_position()
        box_w, box_h = box.width * fig.get_figwidth() * 72, box.height * fig.get_figheight() * 72  # points
        if (x1 - x0) / (y1 - y0) < box_w / box_h:
            grow = ((y1 - y0) * box_w / box_h - (x1 - x0)) / 2
            x0, x1 = x0 - grow, x1 + grow
        else:
            grow = ((x1 - x0) * box_h / box_w - (y1 - y0)) / 2
            y0, y1 = y0 - grow, y1 + grow
        ax.set_xlim((x1, x0) if flip < 0 else (x0, x1))
        ax.set_ylim(y0, y1)
        ax.set_aspect("equal", adjustable="box")
        cm_per_pt = (x1 - x0) / box_w
        screen_box = (min(flip * x0, flip * x1), y0, max(flip * x0, flip * x1), y1)

        out_dirs: dict[str, list[np.ndarray]] = {n.id: [] for n in spec.nodes}  # screen directions leaving a node
        obstacles: list[tuple[np.ndarray, np.ndarray, float]] = []  # screen segments labels should avoid, weight

        # kinematic skeleton
        for a, b, _ in skeleton:
            ax.plot([a[hi], b[hi]], [a[vi], b[vi]], color="#9a9a9a", lw=0.8, zorder=1, solid_capstyle="round")
            obstacles.append((screen(a), screen(b), 0.3))
        # graph edges node → parent
        for n in spec.nodes:
            if n.parent is not None and n.parent in anchors:
                a, b = anchors[n.id], anchors[n.parent]
                ax.plot([a[hi], b[hi]], [a[vi], b[vi]], color="black", lw=2.2, zorder=2)
                out_dirs[n.id].append(screen(b - a))
                out_dirs[n.parent].append(screen(a - b))
                obstacles.append((screen(a), screen(b), 1.0))
        # nodes
        for n in spec.nodes:
            p = anchors[n.id]
            ax.scatter([p[hi]], [p[vi]], s=40, color=NODE_COLORS[n.type], edgecolors="black", linewidths=0.6,
                       zorder=4)
        # joint axes × sign, drawn over the node markers; an axis along the view direction is a ⊙/⊗
        # symbol, drawn once per (place, symbol, colour) and growing when different ones share a place
        symbols: dict[tuple, int] = {}
        rings: dict[int, int] = {}  # spot → number of symbols drawn there
        frame_label: list[tuple[float, float, float, float]] = []  # the ⊙/⊗ palm axis label's rectangle

        places: list[np.ndarray] = []

        def place(v: np.ndarray) -> int:  # index of the spot (nearby points share one) where v is drawn
            q = screen(v)
            for i, c in enumerate(places):
                if np.linalg.norm(c - q) < 0.02 * span:
                    return i
            places.append(q)
            return len(places) - 1

        for (start, d, prim), node_id in zip(arrows, arrow_nodes):
            vec = d * ARROW_LEN * SCALE
            if _is_arrow(vec, hi, vi):
                _draw_arrow(ax, start, vec, hi, vi, PRIMITIVE_COLORS[prim], lw=1.6, zorder=5)
                out_dirs[node_id].append(screen(vec))
                obstacles.append((screen(start), screen(start + vec), 1.0))
            else:
                key = (place(start), vec[ti] > 0, prim)
                if key not in symbols:
                    symbols[key] = rings.get(place(start), 0)
                    rings[place(start)] = symbols[key] + 1
                    _draw_symbol(ax, start, vec, hi, vi, ti, PRIMITIVE_COLORS[prim], ring=symbols[key], zorder=5)
        # palm frame axes f and n at the origin
        for k, label in ((0, "f"), (2, "n")):
            e = np.zeros(3)
            e[k] = FRAME_LEN * SCALE
            if _is_arrow(e, hi, vi):
                _draw_arrow(ax, np.zeros(3), e, hi, vi, FRAME_COLOR, lw=1.4, zorder=3, label=label, dashed=True)
                obstacles.append((screen(np.zeros(3)), screen(e), 1.0))
                out_dirs.setdefault("wrist", []).append(screen(e))
            else:
                ring = rings.get(place(np.zeros(3)), 0)
                rings[place(np.zeros(3))] = ring + 1
                right = -(9 + 3 * ring) * cm_per_pt  # matches _draw_symbol's label offset
                frame_label.append((right - 8 * cm_per_pt, -5 * cm_per_pt, right, 5 * cm_per_pt))
                _draw_symbol(ax, np.zeros(3), e, hi, vi, ti, FRAME_COLOR, ring=ring, zorder=4.5, label=label)
                out_dirs.setdefault("wrist", []).append(np.array([-1.0, 0.0]))  # the symbol's label sits left

        # node labels: nodes that coincide in this view share one label; each label goes to the
        # side of its node that collides least with edges, arrows, other nodes and other labels
        clusters: list[list] = []
        for n in spec.nodes:
            p = screen(anchors[n.id])
            for c in clusters:
                if np.linalg.norm(c[0] - p) < LABEL_MERGE * span:
                    c[1].append(n.id)
                    break
            else:
                clusters.append([p, [n.id]])
        node_pts = [c[0] for c in clusters]
        # obstacle segments sampled at 25 points each: (K, 25, 2) screen cm, and their weights
        t = np.linspace(0.0, 1.0, 25)[None, :, None]
        seg_a = np.array([o[0] for o in obstacles]).reshape(-1, 1, 2)
        seg_b = np.array([o[1] for o in obstacles]).reshape(-1, 1, 2)
        samples = seg_a + t * (seg_b - seg_a)
        obstacle_w = np.array([o[2] for o in obstacles], dtype=float)
        placed: list[tuple[float, float, float, float]] = list(frame_label)
        for p, ids in clusters:
            dirs = [d / np.linalg.norm(d) for i in ids for d in out_dirs.get(i, []) if np.linalg.norm(d) > 1e-9]
            text = "\n".join(ids)
            w = LABEL_SIZE * 0.58 * max(len(i) for i in ids) * cm_per_pt
            h = LABEL_SIZE * 1.2 * len(ids) * cm_per_pt
            spot = next((i for i, q in enumerate(places) if np.linalg.norm(q - p) < 0.02 * span), None)
            n_rings = rings.get(spot, 0) if spot is not None else 0
            offset = LABEL_OFFSET if n_rings == 0 else (13 + 6 * (n_rings - 1)) / 2 + 2.0
            best = None
            for rank, c in enumerate(_LABEL_DIRS):
                o = p + c * offset * cm_per_pt
                rx0 = o[0] if c[0] > 0.3 else o[0] - w if c[0] < -0.3 else o[0] - w / 2
                ry0 = o[1] if c[1] > 0.3 else o[1] - h if c[1] < -0.3 else o[1] - h / 2
                rect = (rx0, ry0, rx0 + w, ry0 + h)
                score = 3.0 * max([0.0] + [float(c @ d) for d in dirs]) + 0.02 * rank
                score += 4.0 * float(obstacle_w @ _samples_hit(samples, rect))
                score += 6.0 * sum(_rects_overlap(rect, r) for r in placed)
                score += 4.0 * sum(_point_in(q, rect, 3 * cm_per_pt) for q in node_pts if q is not p)
                score += 0.0 if _rect_inside(rect, screen_box) else 10.0
                if best is None or score < best[0]:
                    best = (score, c, rect)
            _, c, rect = best
            placed.append(rect)
            ha = "left" if c[0] > 0.3 else "right" if c[0] < -0.3 else "center"
            va = "bottom" if c[1] > 0.3 else "top" if c[1] < -0.3 else "center"
            ax.annotate(text, (flip * p[0], p[1]), xytext=tuple(c * offset), textcoords="offset points",
                        fontsize=LABEL_SIZE, color="#202020", ha=ha, va=va, zorder=3.5, linespacing=1.0,
                        parse_math=False)

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
    handles += [Line2D([], [], color=FRAME_COLOR, lw=1.4, ls="--", label="palm frame f, n"),
                Line2D([], [], ls="none", marker="$\\odot$", ms=9, color="#555555", label="axis toward viewer"),
                Line2D([], [], ls="none", marker="$\\otimes$", ms=9, color="#555555", label="axis away from viewer")]
    fig.legend(handles=handles, loc="lower center", ncol=8, fontsize=8, frameon=False)

    import io

    from dgz_cli.spec.io import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=110)
    # never replaces a device/FIFO/folder, writes through symlinks, OSError → one line (docs/security.md)
    atomic_write_bytes(Path(out), buf.getvalue())


_LABEL_DIRS = [np.array(d, dtype=float) / np.linalg.norm(d)
               for d in ((1, 1), (-1, 1), (1, -1), (-1, -1), (1, 0), (-1, 0), (0, 1), (0, -1))]


def _point_in(q, rect, grow: float = 0.0) -> bool:
    return rect[0] - grow <= q[0] <= rect[2] + grow and rect[1] - grow <= q[1] <= rect[3] + grow


def _samples_hit(samples: np.ndarray, rect) -> np.ndarray:
    """(K,) 0/1: whether any of each segment's sample points (K, S, 2) falls inside ``rect``."""
    x, y = samples[..., 0], samples[..., 1]
    inside = (x >= rect[0]) & (x <= rect[2]) & (y >= rect[1]) & (y <= rect[3])
    return inside.any(axis=1).astype(float)


def _rects_overlap(r, s) -> bool:
    return r[0] < s[2] and s[0] < r[2] and r[1] < s[3] and s[1] < r[3]


def _rect_inside(r, box) -> bool:
    return r[0] >= box[0] and r[1] >= box[1] and r[2] <= box[2] and r[3] <= box[3]


def _is_arrow(vec, hi, vi) -> bool:
    """False when ``vec`` points mostly along the view direction (drawn as ⊙/⊗ instead)."""
    length = float(np.linalg.norm(vec))
    return length > 0 and float(np.hypot(vec[hi], vec[vi])) >= 0.4 * length


def _draw_arrow(ax, start, vec, hi, vi, color, lw, zorder, label=None, dashed=False) -> None:
    x0, y0, dx, dy = start[hi], start[vi], vec[hi], vec[vi]
    ax.annotate("", xy=(x0 + dx, y0 + dy), xytext=(x0, y0), zorder=zorder,
                arrowprops=dict(arrowstyle="-|>", color=color, lw=lw, mutation_scale=9, shrinkA=0, shrinkB=0,
                                ls="--" if dashed else "-"))
    if label:
        ax.annotate(label, (x0 + dx, y0 + dy), xytext=(3, 3), textcoords="offset points", fontsize=10,
                    color=color, fontweight="bold", zorder=zorder)


def _draw_symbol(ax, start, vec, hi, vi, ti, color, ring, zorder, label=None) -> None:
    """⊙ (toward the viewer) or ⊗ (away) at ``start``; ``ring`` > 0 enlarges it around earlier ones."""
    # ti is toward the viewer in both views (front: +n; side: the view looks along −l)
    marker = "$\\odot$" if vec[ti] > 0 else "$\\otimes$"
    ax.plot([start[hi]], [start[vi]], ls="none", marker=marker, ms=13 + 6 * ring, color=color, zorder=zorder)
    if label:
        ax.annotate(label, (start[hi], start[vi]), xytext=(-9 - 3 * ring, 0), textcoords="offset points",
                    fontsize=10, color=color, fontweight="bold", zorder=zorder, ha="right", va="center")
