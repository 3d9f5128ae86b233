"""The finger lead cap (contract action.finger_max_lead) against no cap, for the guided scripted grasp and the
closing prior alone (zero residual, close_guide 0.08), same start states as tools/probe_prior_variants.py
(guidance 0.05, narrow roll, Markov layout, 10 objects × 2 slots × 1 episode per hand). With position control
the grip torque is finger_kp × (target − q), so a cap on the lead also caps the grip.
Run: DGZ_ASSET_ROOT=../shared/assets .venv/bin/python tools/probe_lead_cap.py [HANDS] [VARIANTS]"""
from probe_common import main
from probe_prior_variants import HANDS, run

from dgz_cli.spec.contract import ActionLayout, ClosingPrior

PRIOR = ClosingPrior(enabled=True, close_guide=0.08)
VARIANTS = {f"{name} lead {cap}": (prior, cap) for cap in (None, 0.2)
            for name, prior in (("scripted", None), ("prior guide.08", PRIOR))}

if __name__ == "__main__":
    main(VARIANTS, lambda spec, v: run(spec, v[0], ActionLayout(finger_max_lead=v[1])), HANDS)
