#!/usr/bin/env bash
# Re-generate every shipped spec hand_specs/<hand>/spec.yaml from its URDF (vendor URDFs under $DGZ_ASSET_ROOT),
# with the human overrides of hand_specs/<hand>/overrides.yaml where the hand has them.
set -euo pipefail
cd "$(dirname "$0")/.."
: "${DGZ_ASSET_ROOT:?set DGZ_ASSET_ROOT to the folder holding hands/ (e.g. ../shared/assets)}"
DGZ=${DGZ:-.venv/bin/dgz}
H="$DGZ_ASSET_ROOT/hands"
onboard() { # name urdf
  local ov=hand_specs/$1/overrides.yaml
  if [ -f "$ov" ]; then "$DGZ" onboard "$2" --name "$1" -o "hand_specs/$1/spec.yaml" --overrides "$ov" >/dev/null
  else "$DGZ" onboard "$2" --name "$1" -o "hand_specs/$1/spec.yaml" >/dev/null; fi
  echo "onboarded $1"
}
onboard allegro "$H/allegro/urdf/allegro_hand_right.urdf"
onboard shadow "$H/shadow/urdf/shadow_hand_right.urdf"
onboard schunk_svh "$H/schunk_svh/urdf/schunk_svh_hand_right.urdf"
onboard ability "$H/ability/urdf/ability_hand_right.urdf"
onboard leap "$H/leap/urdf/leap_hand_right.urdf"
onboard inspire "$H/inspire/urdf/inspire_hand_right.urdf"
onboard revo2 "$H/revo2/urdf/revo2_right.urdf"
onboard barrett "$H/barrett/urdf/bhand_model.urdf"
onboard dgz_tri dgz_cli/data/hands/dgz_tri.urdf
