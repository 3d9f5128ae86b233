"""One hand, one folder: ``hand_specs/<hand>/`` holds spec.yaml, overrides.yaml, hardware.yaml and a README,
and every loader finds them by hand name, by folder or by file path."""

from __future__ import annotations

import pytest

from conftest import SPECS, shipped_specs
from dgz_cli.hw.config import hand_config_path, load_hand_config, shipped_hand_configs
from dgz_cli.spec.catalog import hand_name, resolve_spec, shipped_hands
from dgz_cli.spec.errors import SpecError
from dgz_cli.spec.io import load_overrides, load_spec

HANDS = [p.parent.name for p in shipped_specs()]


@pytest.mark.parametrize("hand", HANDS)
def test_folder_is_complete_and_consistent(hand):
    folder = SPECS / hand
    spec = load_spec(folder / "spec.yaml")
    assert spec.name == hand
    assert (folder / "README.md").is_file()
    assert set(p.name for p in folder.iterdir()) <= {"spec.yaml", "overrides.yaml", "hardware.yaml", "README.md"}
    if (folder / "overrides.yaml").is_file():  # the spec embeds exactly what its overrides file says
        assert load_overrides(folder / "overrides.yaml") == spec.overrides
    if (folder / "hardware.yaml").is_file():
        assert resolve_spec(load_hand_config(hand).spec) == folder / "spec.yaml"


def test_names_folders_and_files_resolve_alike():
    assert shipped_hands() == HANDS
    spec = SPECS / "leap" / "spec.yaml"
    assert resolve_spec("leap") == spec
    assert resolve_spec(str(SPECS / "leap")) == spec
    assert resolve_spec(str(spec)) == spec
    assert hand_name(spec) == "leap" and hand_name(SPECS / "leap") == "leap"
    with pytest.raises(SpecError, match="holds no spec.yaml"):
        resolve_spec(str(SPECS.parent / "tests"))


def test_hardware_files_resolve_by_name_folder_and_path():
    assert shipped_hand_configs() == ["inspire", "leap", "revo2"]
    path = SPECS / "revo2" / "hardware.yaml"
    assert hand_config_path("revo2") == path
    assert hand_config_path(str(SPECS / "revo2")) == path
    assert hand_config_path(str(path)) == path


def test_a_symlinked_asset_root_gives_a_relative_reference(tmp_path):
    """Through a symlink to the asset root (or to a folder inside it), a spec still records its URDF relative
    to the root, so re-onboarding reproduces the shipped spec wherever the assets are mounted."""
    from dgz_cli.spec.catalog import PACKAGE_DATA, urdf_reference

    real = tmp_path / "real"
    (real / "hands" / "tri").mkdir(parents=True)
    urdf = real / "hands" / "tri" / "tri.urdf"
    urdf.write_bytes((PACKAGE_DATA / "hands" / "dgz_tri.urdf").read_bytes())
    link = tmp_path / "link"
    link.symlink_to(real)
    assert urdf_reference(link / "hands" / "tri" / "tri.urdf", link) == "hands/tri/tri.urdf"
    assert urdf_reference(urdf, link) == "hands/tri/tri.urdf"
    assert urdf_reference(link / "hands" / "tri" / "tri.urdf", real) == "hands/tri/tri.urdf"
