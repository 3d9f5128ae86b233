"""What in the simulated physics bounds grasp success? Runs ``dgz eval`` in this process with one physical
parameter of every scene changed:

- ``condim=N``: every collision geom of the object gets MuJoCo contact dimensionality N (the env's, and MuJoCo's
  default, is 3: sliding friction only; 4 adds torsional friction about the contact normal, 6 also rolling
  friction; the coefficients are the env's own, ``friction=[1.0, 0.005, 0.0001]``, of which condim 3 uses only
  the first). A contact takes the larger condim of its two geoms: this changes the object's contacts with the
  hand and with the table.
- ``effort=K``: every finger actuator's force limit (the URDF's joint ``effort``, N·m or N) is multiplied by K;
  joints without a limit stay unlimited. (Before session 37 the scene also kept the limit MuJoCo's URDF import
  puts on each joint, ``actuatorfrcrange``, which this probe did not scale: its ``effort`` runs then changed
  nothing. The scene now keeps the limit on the actuator only.)
- ``kp=K``: every finger actuator's position gain (the env's ``finger_kp``, the same for every hand) is multiplied
  by K, with the damping ratio kept at 1.

`DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_physics.py CHANGE eval ARGS...`
(ARGS as `dgz eval`'s, e.g. `--policy scripted --roll clear --thumb-open 0.5 --guidance 0.05 --hand leap
--objects ycb45 --trials 5 --settle 2 --json out.json`). A probe of the simulator, not an option of the env."""
import sys

import dgz_cli.sim.scene as scene


def _patch(change: str) -> None:
    key, _, value = change.partition("=")
    factor = float(value) if value.replace(".", "", 1).isdigit() and float(value) > 0 else None
    if key == "condim" and value in {"1", "3", "4", "6"}:
        object_spec, condim = scene.object_spec, int(value)

        def object_spec_with_condim(obj, visual):
            s = object_spec(obj, visual)
            for g in s.worldbody.first_body().geoms:
                if g.contype != 0:
                    g.condim = condim
            return s

        scene.object_spec = object_spec_with_condim
    elif key == "effort" and factor is not None:
        position_actuator = scene._position_actuator

        def position_actuator_with_effort(world, joint, kp, effort):
            position_actuator(world, joint, kp, None if effort is None else effort * factor)

        scene._position_actuator = position_actuator_with_effort
    elif key == "kp" and factor is not None:
        position_actuator = scene._position_actuator

        def position_actuator_with_kp(world, joint, kp, effort):
            finger = joint.startswith(scene.HAND_PREFIX)
            position_actuator(world, joint, kp * factor if finger else kp, effort)

        scene._position_actuator = position_actuator_with_kp
    else:
        sys.exit(f"{change!r}: give condim=1|3|4|6, effort=K or kp=K (K > 0)")


def main() -> None:
    if len(sys.argv) < 3 or sys.argv[2] != "eval":
        sys.exit(__doc__.splitlines()[-3])
    _patch(sys.argv[1])
    from dgz_cli.cli.app import main as dgz_main

    sys.argv = ["dgz", *sys.argv[2:]]
    dgz_main()


if __name__ == "__main__":
    main()
