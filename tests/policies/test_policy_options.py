"""Each policy plugin's options model (``PolicyType.options``): its defaults stated once, the ``policy`` group
validated with it before any output (one line naming ``policy.<key>``), the factory given the validated options."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from eval_runs import refusal
from molmo_lerobot.config import compose, primary_config_dir
from molmo_lerobot.context import RunContext
from molmo_lerobot.options import OptionsError, validate_group
from molmo_lerobot.plugins import Plugins
from molmo_lerobot.policies.base import OpenPolicyOptions, PolicyOptions
from molmo_lerobot.policies.factory import make_policy, policy_options
from molmo_lerobot.policies.random_policy import RandomOptions, RandomPolicy
from molmo_lerobot.run_config import RunConfig, config_problems
from molmo_lerobot.runner.evaluate import plugin_option_problems


@pytest.fixture(scope="module")
def plugins() -> Plugins:
    return Plugins()


def _problems(*overrides: str) -> list[str]:
    return plugin_option_problems(RunContext.build(RunConfig.of(compose(list(overrides)))))


def _defaults(model: type[PolicyOptions]) -> dict:
    return model.model_construct().model_dump()


def test_every_policy_declares_a_closed_options_model(plugins):
    for name in plugins.names("policy"):
        model = plugins.policy(name).options
        assert issubclass(model, PolicyOptions) and model is not OpenPolicyOptions, name
        assert model.model_config.get("extra") == "forbid", name


def test_a_policy_yaml_states_no_default_of_its_own(plugins):
    """``conf/policy/<name>.yaml`` (and a plugin's own) may repeat a default of the model, never state
    another: each key it gives is the model's default (``???``: Hydra's "must be given")."""
    checked = []
    for name in plugins.names("policy"):
        model = plugins.policy(name).options
        dirs = [primary_config_dir(), *map(Path, plugins.config_dirs())]
        if not any((d / "policy" / f"{name}.yaml").is_file() for d in dirs):
            continue
        given = OmegaConf.to_container(compose([f"policy={name}"]).policy)
        defaults = _defaults(model)
        differ = {k: (v, defaults.get(k, "(no such key)")) for k, v in given.items()
                  if v != "???" and v != defaults.get(k, "(no such key)")}
        assert differ == {}, f"policy/{name}.yaml: {differ}"
        checked.append(name)
    assert {"lerobot", "random", "remote", "replay", "scripted", "pi0"} <= set(checked)


def test_an_unknown_policy_key_is_refused_naming_it():
    """Before: ``policy=random +policy.sclae=0.3`` ran with scale 0.15, the typo unread."""
    line = _problems("policy=random", "+policy.sclae=0.3")
    assert line == [f"policy.sclae: unknown key (known: {', '.join(RandomOptions.model_fields)})"]
    assert _problems("policy=remote", "+policy.hots=gpu-box")[0].startswith("policy.hots: unknown key (known: name, ")
    assert _problems("policy=scripted", "+policy.chunck=4", "+policy.sped=2")[0].startswith(
        "policy.chunck, policy.sped: unknown keys (known: name, ")
    # the keys every policy shares are typed in the run config itself
    assert config_problems(compose(["policy=random", "policy.convention=droid"])) == [
        "policy.convention: input should be 'native' or 'molmospaces', got 'droid'"]


def test_a_run_refuses_an_unknown_policy_key_before_any_output(tmp_path):
    out = tmp_path / "out"
    assert refusal("policy=random", "+policy.sclae=0.3", "limit=1", f"output_dir={out}") == [
        f"policy.sclae: unknown key (known: {', '.join(RandomOptions.model_fields)})"]
    assert not out.exists()


def test_a_policy_without_a_model_keeps_its_own_keys(plugins):
    """A third-party policy that declares no model: the shared keys are checked, its own kept as given."""
    options = policy_options(plugins, {"name": "random"})
    assert isinstance(options, RandomOptions)
    open_options = OpenPolicyOptions.model_validate({"name": "sine", "amplitude": 0.3})
    assert open_options.model_dump() == {**_defaults(PolicyOptions), "name": "sine", "amplitude": 0.3}
    with pytest.raises(OptionsError, match=r"^policy.serve: expected true or false, got 'yes'$"):
        validate_group("policy", OpenPolicyOptions, {"name": "sine", "serve": "yes"})


def test_a_policys_default_comes_from_its_model(plugins):
    """``conf/policy/random.yaml`` states no scale or chunk; the policy built from it has the model's."""
    composed = OmegaConf.to_container(compose(["policy=random"]).policy)
    assert "scale" not in composed and "chunk" not in composed
    policy = make_policy(plugins, composed)
    assert isinstance(policy, RandomPolicy)
    assert (policy.scale, policy.chunk) == (RandomOptions().scale, RandomOptions().chunk) == (0.15, 8)
    built = make_policy(plugins, {"name": "random", "chunk": 3})
    assert built.chunk == 3 and built.scale == 0.15


def test_the_factory_gets_the_validated_options_as_a_dict(plugins, tmp_path):
    actions = tmp_path / "a.npy"
    np.save(actions, np.zeros((2, 8)))
    with pytest.raises(OptionsError, match=r"^policy.actions: missing; give policy.actions=<file.npy>"):
        make_policy(plugins, {"name": "replay"})
    assert make_policy(plugins, {"name": "replay", "actions": str(actions)}).actions.shape == (2, 8)
    assert _problems("policy=replay") == [
        "policy.actions: missing; give policy.actions=<file.npy> (an array of shape (T, n))"]


def test_run_json_keeps_the_policy_group_as_given(tmp_path, fork_servers):
    """What a resume compares is unchanged: ``run.json``'s ``options.policy`` is the group as composed, not
    the model's dump (a run stored before the models existed resumes)."""
    from molmo_lerobot.runner.evaluate import run_evaluation

    out = tmp_path / "run"
    run_evaluation(compose(["policy=random", "limit=1", "workers=1", "horizon=2", "progress=false",
                            f"output_dir={out}"]), fork_servers)
    stored = json.loads((out / "run.json").read_text())["options"]["policy"]
    assert stored == {"name": "random", "convention": "native"}
    assert os.path.isfile(out / "episodes.jsonl")
