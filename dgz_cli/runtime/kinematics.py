"""Forward kinematics of the hand alone, for the deploy runtime: :class:`HandKinematics` lives in
:mod:`dgz_cli.spec.kinematics` (the one implementation onboarding, the sim and the hardware backends share);
this module keeps the runtime's import path."""

from dgz_cli.spec.kinematics import HandKinematics

__all__ = ["HandKinematics"]
