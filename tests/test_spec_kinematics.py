"""The one forward-kinematics implementation (dgz_cli.spec.kinematics) as onboarding, the sim scene and the
runtime use it: they agree with each other on the built-in hand, mimics included."""

from __future__ import annotations

import numpy as np

from conftest import SPECS
from dgz_cli.onboard.compile import Poser, compile_model
from dgz_cli.onboard.urdf import load_kinematics
from dgz_cli.sim.scene import palm_in_root
from dgz_cli.spec.catalog import resolve_urdf
from dgz_cli.spec.io import load_spec
from dgz_cli.spec.kinematics import HandKinematics, hand_xml, rest_pose

TRI = load_spec(SPECS / "dgz_tri" / "spec.yaml")


def test_rest_pose_is_zero_clipped_into_the_limits():
    assert rest_pose([-1.0, 0.2, -0.5], [1.0, 0.9, -0.1]).tolist() == [0.0, 0.2, -0.1]
    lo, hi = np.array([[r.lower, r.upper] for r in TRI.joints]).T
    np.testing.assert_array_equal(TRI.rest_pose(), np.clip(0.0, lo, hi))


def test_onboarding_poser_and_runtime_kinematics_agree_with_mimics():
    urdf = load_kinematics(resolve_urdf(TRI.provenance.urdf), TRI.provenance.xacro_args)
    poser = Poser(urdf, compile_model(urdf))
    kin = HandKinematics(TRI)
    lo, hi = np.array([[r.lower, r.upper] for r in TRI.joints]).T
    q = np.random.default_rng(0).uniform(lo, hi)
    poser.pose({r.joint: float(v) for r, v in zip(TRI.joints, q)})
    kin.pose(q)
    for m in TRI.mimic:  # the mimic joint follows its source in both
        source = q[[r.joint for r in TRI.joints].index(m.source)]
        j = urdf.joints[m.joint]
        assert poser.value(m.joint) == kin.fk.value(m.joint) == np.clip(m.multiplier * source + m.offset,
                                                                         j.lower, j.upper)
    by_poser = np.array([poser.link_pos(n.anchor_link, np.array(n.anchor_point)) for n in TRI.nodes])
    np.testing.assert_allclose(kin.anchors_root(), by_poser, atol=1e-12)


def test_scene_palm_frame_is_the_runtime_one():
    import mujoco

    kin = HandKinematics(TRI)
    kin.pose(TRI.rest_pose())
    axes, center = palm_in_root(TRI, mujoco.MjSpec.from_string(hand_xml(TRI)))
    np.testing.assert_array_equal(axes, kin.palm_frame()[0])
    np.testing.assert_array_equal(center, kin.palm_frame()[1])
