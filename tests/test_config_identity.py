"""A run's identity (rbstab.config.identity): the hashes of the shipped configurations and
of stored results stay what the files and sweep run ids already hold, so resume keeps
recognising results written before."""

import json
import warnings
from pathlib import Path

import pytest
import yaml

from rbstab.config import RUN_LIMIT_KEYS, canonical_config, canonical_configs, config_hash, load_config
from rbstab.io.chunk import read_chunk_rows
from rbstab.io.hdf5 import read_attributes

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"

#: config_hash of each shipped configuration (without and with its run limits), as the
#: run-file writer computed them when the identity moved to rbstab.config.
PINNED = {
    "configs/examples/free_gravity.yaml": (
        "055d2c25b7081163ba443dfde75fe63f19b528d53ae0d95e7d642830e62bae3a",
        "89a5f809466cdb8bc05f05f6f7593be04c94b76630bcd50c50067b74478bf264"),
    "configs/examples/sliding.yaml": (
        "469f76157f5555d3dc2c6102e133b49747d465ddb9b6e44830c4924b3bbf2833",
        "5ae2ce51ce281e2b5f4730540fe941adf618701e10fe8bce5a60813cfc990dfd"),
    "configs/paper/case1_permanent.yaml": (
        "abeaff0536212e9700e025d215127f49aedcffb8de01bbda24da89ee205ea7e7",
        "6c2f199fc7b41f1f14ff0bf70aac0efbed8e18979e980600f33523d8fa81514d"),
    "configs/paper/case2_visco_elastic.yaml": (
        "49a58317269e0d23349a17c6c54ba2339b4ed6afb9d45b0381b1969c69af7fea",
        "4f2971d1356d6e80129037350c5b3f03788778b9c528d537e3e1c29cf239c478"),
    "configs/paper/case3_embedded.yaml": (
        "fac36d153bf4938993c32a2cb2c1b2ee4fe279f78d2a743066bfbc710bcdf948",
        "9547dd37fcb5b23f8ad4f4223fbe0bc15c79a04f9317c7cfbf3ffc63d0c1d044"),
}


def _load(name: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the paper's inertia: a plausibility note
        return load_config(ROOT / name)


@pytest.mark.parametrize("name", sorted(PINNED))
def test_hashes_of_the_shipped_configurations_are_unchanged(name):
    resolved = _load(name).resolved
    identity, full = canonical_configs(resolved)
    assert (config_hash(canonical_config(resolved)), config_hash(canonical_config(resolved, limits=True))) \
        == PINNED[name]
    assert (config_hash(identity), config_hash(full)) == PINNED[name]


def test_the_identity_leaves_out_the_name_and_the_run_limits_only():
    resolved = _load("configs/paper/case3_embedded.yaml").resolved
    renamed = {**resolved, "name": "other"}
    limited = {**resolved, "simulation": {**resolved["simulation"], **dict.fromkeys(RUN_LIMIT_KEYS, 7)}}
    changed = {**resolved, "simulation": {**resolved["simulation"], "rtol": 1e-7}}
    assert config_hash(canonical_config(renamed)) == config_hash(canonical_config(resolved))
    assert config_hash(canonical_config(limited)) == config_hash(canonical_config(resolved))
    assert canonical_config(limited, limits=True) != canonical_config(resolved, limits=True)
    assert config_hash(canonical_config(changed)) != config_hash(canonical_config(resolved))


def test_stored_results_keep_their_identity():
    """A run file (YAML config) and a store file (canonical JSON with the limits) written by
    an earlier version: the hash of their stored config is the hash they hold."""
    attrs = read_attributes(DATA / "run_file_6596935.h5")
    assert config_hash(canonical_config(yaml.safe_load(attrs["config"]))) == attrs["config_hash"]
    rows = read_chunk_rows(DATA / "store_file_6596935.h5")
    assert rows
    for row in rows:
        stored = json.loads(row["config"])
        assert canonical_config(stored, limits=True) == row["config"]
        assert config_hash(canonical_config(stored)) == row["config_hash"]
