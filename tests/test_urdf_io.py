"""Mesh path resolution, foreign <mujoco> elements and the one-way import rule."""

from __future__ import annotations

import subprocess
import sys

import pytest

from conftest import BUILTIN, REPO
from dgz_cli.onboard.compile import compile_with_warnings
from dgz_cli.onboard.urdf import load_kinematics
from dgz_cli.spec.errors import UrdfError

CUBE_OBJ = "".join(f"v {x} {y} {z}\n" for x in (-0.01, 0.01) for y in (-0.01, 0.01) for z in (0, 0.04)) + """\
f 1 3 4 2
f 5 6 8 7
f 1 2 6 5
f 3 7 8 4
f 1 5 7 3
f 2 4 8 6
"""


def _urdf_with_mesh(filename: str, extra: str = "") -> str:
    return f"""<robot name="m">{extra}
  <link name="palm"><inertial><mass value="0.2"/><inertia ixx="1e-4" iyy="1e-4" izz="1e-4" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><box size="0.08 0.02 0.08"/></geometry></collision></link>
""" + "".join(f"""
  <link name="f{i}"><inertial><mass value="0.02"/><inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><geometry><mesh filename="{filename}"/></geometry></collision></link>
  <joint name="j{i}" type="revolute"><parent link="palm"/><child link="f{i}"/>
    <origin xyz="{x} 0 0.05"/><axis xyz="-1 0 0"/><limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>""" for i, x in ((1, -0.02), (2, 0.02))) + "\n</robot>\n"


@pytest.mark.parametrize("style", ["relative", "absolute", "package"])
def test_mesh_paths_resolve(tmp_path, style):
    pkg = tmp_path / "my_hand_description"
    (pkg / "meshes").mkdir(parents=True)
    (pkg / "urdf").mkdir()
    mesh = pkg / "meshes" / "cube.obj"
    mesh.write_text(CUBE_OBJ)
    ref = {"relative": "../meshes/cube.obj", "absolute": str(mesh),
           "package": "package://my_hand_description/meshes/cube.obj"}[style]
    urdf = pkg / "urdf" / "hand.urdf"
    urdf.write_text(_urdf_with_mesh(ref))
    kin = load_kinematics(urdf)
    assert kin.meshes == (mesh.resolve(),) * 2
    model, _ = compile_with_warnings(kin)
    assert model.nmesh >= 1


def test_missing_mesh_is_named(tmp_path):
    urdf = tmp_path / "hand.urdf"
    urdf.write_text(_urdf_with_mesh("meshes/nope.obj"))
    with pytest.raises(UrdfError, match=r"missing mesh file meshes/nope.obj \(link 'f1'\) and 1 more"):
        load_kinematics(urdf)


def test_foreign_mujoco_element_is_replaced(tmp_path):
    (tmp_path / "cube.obj").write_text(CUBE_OBJ)
    urdf = tmp_path / "hand.urdf"
    urdf.write_text(_urdf_with_mesh("cube.obj", extra='<mujoco><compiler meshdir="/nonexistent" fusestatic="true"/></mujoco>'))
    model, _ = compile_with_warnings(load_kinematics(urdf))  # would fail with the file's own meshdir
    assert model.njnt == 2


def test_builtin_urdfs_are_generated_by_the_tool(tmp_path):
    """The shipped primitive hands are exactly what tools/make_builtin_hands.py writes."""
    before = {p.name: p.read_text() for p in BUILTIN.glob("*.urdf")}
    src = (REPO / "tools" / "make_builtin_hands.py").read_text()
    assert "OUT = Path(__file__).resolve().parents[1]" in src
    script = tmp_path / "tools" / "make_builtin_hands.py"
    script.parent.mkdir()
    script.write_text(src)
    (tmp_path / "dgz_cli" / "data" / "hands").mkdir(parents=True)
    subprocess.run([sys.executable, str(script)], check=True, capture_output=True)
    after = {p.name: p.read_text() for p in (tmp_path / "dgz_cli" / "data" / "hands").glob("*.urdf")}
    assert after == before
