"""Generates the primitive-shape hand URDFs shipped in dgz_cli/data/hands (run: python tools/make_builtin_hands.py)."""
import math
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "dgz_cli" / "data" / "hands"
GAP = 0.002  # clearance at each end of a phalanx cylinder
KNUCKLE = 0.012  # abd axis -> mcp axis offset along the finger
DAMP = 0.05
EFFORT, VEL = 1.0, 3.0


def f(v):
    s = f"{v:.10f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def vec(v):
    return " ".join(f(x) for x in v)


def inertial_box(m, sx, sy, sz, xyz=(0, 0, 0)):
    return (m, xyz, (m * (sy**2 + sz**2) / 12, m * (sx**2 + sz**2) / 12, m * (sx**2 + sy**2) / 12))


def inertial_cyl(m, r, h, xyz):
    i = m * (3 * r**2 + h**2) / 12
    return (m, xyz, (i, i, m * r**2 / 2))


def inertial_sph(m, r, xyz=(0, 0, 0)):
    i = 0.4 * m * r**2
    return (m, xyz, (i, i, i))


def link(name, geom, inertial, rgba="0.7 0.7 0.72 1", mat="grey"):
    m, xyz, (ixx, iyy, izz) = inertial
    kind, gxyz, dims = geom
    if kind == "box":
        g = f'<box size="{vec(dims)}"/>'
    elif kind == "cylinder":
        g = f'<cylinder radius="{f(dims[0])}" length="{f(dims[1])}"/>'
    else:
        g = f'<sphere radius="{f(dims[0])}"/>'
    o = f'<origin xyz="{vec(gxyz)}" rpy="0 0 0"/>'
    return f"""  <link name="{name}">
    <inertial>
      <origin xyz="{vec(xyz)}" rpy="0 0 0"/>
      <mass value="{f(m)}"/>
      <inertia ixx="{ixx:.4e}" ixy="0" ixz="0" iyy="{iyy:.4e}" iyz="0" izz="{izz:.4e}"/>
    </inertial>
    <visual>
      {o}
      <geometry>{g}</geometry>
      <material name="{mat}"/>
    </visual>
    <collision>
      {o}
      <geometry>{g}</geometry>
    </collision>
  </link>
"""


def joint(name, jtype, parent, child, xyz, rpy, axis=None, lim=None, mimic=None):
    s = f'  <joint name="{name}" type="{jtype}">\n'
    s += f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
    s += f'    <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>\n'
    if jtype != "fixed":
        s += f'    <axis xyz="{vec(axis)}"/>\n'
        if jtype == "continuous":
            s += f'    <limit effort="{f(EFFORT)}" velocity="{f(VEL)}"/>\n'
        else:
            s += f'    <limit lower="{f(lim[0])}" upper="{f(lim[1])}" effort="{f(EFFORT)}" velocity="{f(VEL)}"/>\n'
        s += f'    <dynamics damping="{f(DAMP)}"/>\n'
        if mimic:
            s += f'    <mimic joint="{mimic[0]}" multiplier="{f(mimic[1])}" offset="{f(mimic[2])}"/>\n'
    s += "  </joint>\n"
    return s


def phalanx(name, length, mass, r):
    h = length - 2 * GAP
    c = (0, 0, length / 2)
    return link(name, ("cylinder", c, (r, h)), inertial_cyl(mass, r, h, c))


def tip(name, r=0.005):
    return link(name, ("sphere", (0, 0, 0), (r,)), inertial_sph(0.01, r), rgba="0.9 0.3 0.2 1", mat="tip")


def palm():
    return link("palm", ("box", (0, 0, 0.05), (0.09, 0.02, 0.10)),
                inertial_box(0.3, 0.09, 0.02, 0.10, (0, 0, 0.05)), rgba="0.35 0.35 0.4 1", mat="palm")


def finger(prefix, base_xyz, s, flex_names, lens, masses, abd_lim, abd_type="revolute",
           mimic_last=None, flex_lim=(-0.1, 1.6)):
    """s = +1 right hand, -1 mirrored (left). Axes in joint frame: flex (-1,0,0), abd s*(0,1,0)."""
    out = []
    r = 0.009
    # Knuckle: sphere centred KNUCKLE above the abduction axis; the MCP axis goes through its centre.
    # The palm is welded to the world, so MuJoCo does NOT filter palm<->child contacts: the knuckle
    # and proximal phalanx are kept clear of the palm box for all abd angles in range / all flexion.
    abd_link = f"{prefix}_knuckle"
    c = (0, 0, KNUCKLE)
    out.append(link(abd_link, ("sphere", c, (r,)), inertial_sph(0.01, r, c)))
    out.append(joint(f"{prefix}_abd", abd_type, "palm", abd_link, base_xyz, (0, 0, 0),
                     (0, s * 1, 0), abd_lim))
    parent, offset = abd_link, KNUCKLE
    seg_names = ["proximal", "middle", "distal"]
    for k, (jn, L, m) in enumerate(zip(flex_names, lens, masses)):
        child = f"{prefix}_{seg_names[k]}"
        out.append(phalanx(child, L, m, r))
        mim = mimic_last if (mimic_last and k == len(flex_names) - 1) else None
        out.append(joint(f"{prefix}_{jn}", "revolute", parent, child, (0, 0, offset), (0, 0, 0),
                         (-1, 0, 0), flex_lim, mimic=mim))
        parent, offset = child, L
    out.append(tip(f"{prefix}_tip"))
    out.append(joint(f"{prefix}_tip_joint", "fixed", parent, f"{prefix}_tip", (0, 0, offset), (0, 0, 0)))
    return out


def THUMB_FLEX(s):
    # flexion curls the thumb across the palm: toward +n and toward the fingers (opposition)
    return (-0.5, s * 0.866025, 0)


def thumb(s):
    out = []
    r = 0.01
    Lm, Lp, Ld = 0.05, 0.035, 0.03
    # metacarpal cylinder only spans t in [0.02, Lm-GAP] along the thumb axis so that it clears the
    # palm box (x >= -0.045) although the thumb_rot axis starts inside the palm at x=-0.04.
    t0 = 0.02
    h = Lm - GAP - t0
    c = (0, 0, t0 + h / 2)
    out.append(link("thumb_metacarpal", ("cylinder", c, (r, h)), inertial_cyl(0.04, r, h, c)))
    # base frame: rotated about y by -s*pi/4 so the thumb points along (-s*0.707, 0, 0.707)
    out.append(joint("thumb_rot", "revolute", "palm", "thumb_metacarpal", (s * -0.04, 0, 0.03),
                     (0, -s * math.pi / 4, 0), (0, 0, s * 1), (0.0, 1.2)))
    out.append(phalanx("thumb_proximal", Lp, 0.03, r))
    out.append(joint("thumb_mcp", "revolute", "thumb_metacarpal", "thumb_proximal", (0, 0, Lm), (0, 0, 0),
                     THUMB_FLEX(s), (0.0, 1.2)))
    out.append(phalanx("thumb_distal", Ld, 0.02, r))
    out.append(joint("thumb_ip", "revolute", "thumb_proximal", "thumb_distal", (0, 0, Lp), (0, 0, 0),
                     THUMB_FLEX(s), (0.0, 1.3)))
    out.append(tip("thumb_tip"))
    out.append(joint("thumb_tip_joint", "fixed", "thumb_distal", "thumb_tip", (0, 0, Ld), (0, 0, 0)))
    return out


def header(name, comment):
    return f"""<?xml version="1.0"?>
<!--
  {comment}
  Made for dgz from primitive shapes only (box / cylinder / sphere, no meshes). MIT licence.
  Conventions: root link "palm"; wrist at z=0; fingers along +z starting at z~0.10;
  palm normal +y; positive flexion curls the fingers toward +y.
-->
<robot name="{name}">
  <material name="palm"><color rgba="0.35 0.35 0.4 1"/></material>
  <material name="grey"><color rgba="0.7 0.7 0.72 1"/></material>
  <material name="tip"><color rgba="0.9 0.3 0.2 1"/></material>
"""


def tri(s):
    desc = ("dgz tri: three-finger RIGHT hand (thumb + index + middle); shipped default." if s > 0 else
            "dgz tri left: three-finger LEFT hand, exact mirror of dgz_tri.urdf through the plane x=0.\n"
            "  Positions x -> -x; joint axes a -> -(M a), M=diag(-1,1,1); names identical to dgz_tri.urdf.")
    parts = [header("dgz_tri" if s > 0 else "dgz_tri_left", desc), palm()]
    lens, masses = (0.045, 0.03, 0.025), (0.03, 0.02, 0.015)
    for name, x in (("index", -0.015), ("middle", 0.015)):
        parts += finger(name, (s * x, 0, 0.10), s, ("mcp", "pip", "dip"), lens, masses, (-0.35, 0.35),
                        mimic_last=(f"{name}_pip", 0.8, 0.0))
    parts += thumb(s)
    parts.append("</robot>\n")
    return "".join(parts)


def quad():
    parts = [header("dgz_quad_continuous",
                    "dgz quad: four identical fingers, no thumb; f2_abd is a continuous joint (test fixture)."),
             palm()]
    for n, x in zip(range(1, 5), (-0.03, -0.01, 0.01, 0.03)):
        parts += finger(f"f{n}", (x, 0, 0.10), 1, ("mcp", "pip", "dip"), (0.045, 0.03, 0.025),
                        (0.03, 0.02, 0.015), (-0.3, 0.3), abd_type="continuous" if n == 2 else "revolute")
    parts.append("</robot>\n")
    return "".join(parts)


if __name__ == "__main__":
    (OUT / "dgz_tri.urdf").write_text(tri(+1))
    (OUT / "dgz_tri_left.urdf").write_text(tri(-1))
    (OUT / "dgz_quad_continuous.urdf").write_text(quad())
    print("written")
