"""Controller specs (rabbit_policy.spec): each shipped controller is one readable file that
names every stage and constant, built by one ``build``; what ships is what the spec says,
whatever the code's defaults."""

from __future__ import annotations

import ast
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Push, Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy, PeriodicPolicy, PolicyUnavailable

from checkpoints import SHIPPED_BEFORE
from rabbit_policy.spec.make import checkpoint_policy, make_policy
from rabbit_policy.runtime.recovery import RecoveryConfig, RecoveryPolicy
from rabbit_policy.spec import SpecError, build, load_controller, load_packaged, load_spec, packaged_spec
from rabbit_policy.spec.schema import KINDS, parse_spec

pytestmark = pytest.mark.sim

SRC = Path(__file__).resolve().parents[2] / "src" / "rabbit_policy" / "rabbit_policy"
# a backward push the rule answers (13 N s at 1.0 m/s: classic stalls), a speed change and a forward push, in 7 s
SCENARIO = Scenario(schedule=((0.0, 1.0), (4.5, 1.3)), pushes=(Push(3.0, -130.0, 0.1), Push(5.5, 100.0, 0.1)))


def _trajectory(policy) -> np.ndarray:
    result = walk(policy, SCENARIO, 7.0, record_state=True)
    return np.hstack([np.asarray(result.qpos), np.asarray(result.qvel)])


@pytest.mark.slow
def test_the_shipped_specs_walk_as_the_controllers_assembled_before_them_bit_for_bit():
    """Classic's and the recovery controller's specs were written from the code's constants:
    built, each walks exactly as the controller the code assembles from them. (The learned one
    is reproduce.py's output: test_training.py and test_reproduce.py hold it.)"""
    library = GaitLibrary.load()
    before = {"classic": PeriodicPolicy(LibraryPolicy(library, "interpolate"), 20),
              "recovery": RecoveryPolicy(LibraryPolicy(library, "interpolate"), decision_period=20)}
    for kind in before:
        spec_built = load_packaged(kind)
        assert np.array_equal(_trajectory(spec_built), _trajectory(before[kind])), kind
        assert spec_built.controller_settings == spec_built.spec.controller.settings()


@pytest.mark.slow
def test_no_code_default_moves_a_shipped_controller(monkeypatch):
    """The recovery rule's constants, the overlay's and the controller's blend defaults are
    changed in the code: the controllers the code assembles from its defaults walk
    differently (the test can fail), the shipped specs' do not move."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_policy.runtime.recovery import OverlayConfig

    shipped = {kind: _trajectory(load_packaged(kind)) for kind in ("recovery", "learned")}
    defaults = list(RecoveryConfig.__init__.__defaults__)
    defaults[0] = (-0.3, 0.1, 0.2, -0.4)  # offsets
    monkeypatch.setattr(RecoveryConfig.__init__, "__defaults__", tuple(defaults))
    blend = list(ControllerConfig.__init__.__defaults__)
    names = [f for f in ControllerConfig.__dataclass_fields__ if ControllerConfig.__dataclass_fields__[f].init]
    blend[names.index("within_step_blend") - (len(names) - len(blend))] = 0.5
    monkeypatch.setattr(ControllerConfig.__init__, "__defaults__", tuple(blend))
    overlay = list(OverlayConfig.__init__.__defaults__)
    overlay[0] = 0.3  # fast_gate
    monkeypatch.setattr(OverlayConfig.__init__, "__defaults__", tuple(overlay))
    assert RecoveryConfig().offsets == (-0.3, 0.1, 0.2, -0.4) and ControllerConfig().within_step_blend == 0.5
    from_defaults = RecoveryPolicy(LibraryPolicy(GaitLibrary.load(), "interpolate"), RecoveryConfig(), 20)
    assert not np.array_equal(_trajectory(from_defaults), shipped["recovery"])
    assert not np.array_equal(_trajectory(checkpoint_policy(SHIPPED_BEFORE)), shipped["learned"])
    for kind in ("recovery", "learned"):
        assert np.array_equal(_trajectory(load_packaged(kind)), shipped[kind]), kind


def _perturbed(value):
    """Another value of a default's kind (a float, a whole number, a tuple of floats)."""
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value * 1.5 + 0.01
    return tuple(v * 1.5 + 0.01 for v in value)


MODEL_OWNED = {"LegGeometry.femur", "LegGeometry.tibia", "ControllerConfig.tick"}
"""Defaults that are the robot model's, not the controller's: a spec names the model by hash
(``controller.model_sha256``) and is refused on another."""
NOT_PERTURBED = {"GaitLibrary.calibration", "IntegralConfig.band", "IntegralConfig.clip", "IntegralConfig.windup_decay",
                 "IntegralConfig.feedforward", "IntegralConfig.speed_range", "DecisionTiming.ticks", "Observation.body",
                 "WindupDecay.disturbance"}
"""Defaults of no number's kind (None: a stage off, or a record's empty slot), which build
gives explicitly from the spec (its ``speed_integral`` section, ``MemoryConfig(integral, body)``). The
windup decay's ``disturbance`` is the one optional key of a spec's rules: absent, the rule is off,
as in every spec written before it."""


def reachable_defaults() -> list[tuple[type, str, int]]:
    """Every (dataclass, field, index in ``__init__.__defaults__``) whose default a shipped walk
    could read: the dataclasses of the runtime, the spec, the 1 kHz law and the decision rule."""
    import dataclasses
    import inspect

    import rabbit_policy.experiment.loop  # noqa: F401 - the loop that walks them, and what it imports
    import rabbit_policy.spec.build  # noqa: F401

    found = []
    prefixes = ("rabbit_policy.runtime", "rabbit_policy.spec", "rabbit_hzd_controller", "rabbit_msgs_py.decision_ticks")
    for name in sorted(m for m in sys.modules if m.startswith(prefixes)):
        for cls in vars(sys.modules[name]).values():
            if not (inspect.isclass(cls) and dataclasses.is_dataclass(cls) and cls.__module__ == name):
                continue
            names = [f.name for f in dataclasses.fields(cls) if f.init and not f.kw_only]
            defaults = cls.__init__.__defaults__ or ()
            for index, value in enumerate(defaults):
                if type(value).__name__ != "_HAS_DEFAULT_FACTORY_CLASS":
                    found.append((cls, names[len(names) - len(defaults) + index], index))
    return found


@pytest.mark.slow
def test_no_code_default_reachable_from_build_or_the_law_moves_a_shipped_walk_one_at_a_time(monkeypatch):
    """Every dataclass default the three shipped controllers could read (the runtime's, the
    spec's, the 1 kHz law's: ``ControllerConfig``'s gains, limits, touchdown rule, coefficient
    ranges and Kd bound included), changed one at a time in the code: the shipped classic,
    recovery and learned walks do not move (their specs name every value). The model's own
    (leg geometry, the tick) do move it: the harness sees a change, and a spec names that model
    by hash."""
    from rabbit_hzd_controller.kinematics import LegGeometry

    shipped = {kind: _trajectory(load_packaged(kind)) for kind in KINDS}
    checked, skipped = [], []
    for cls, name, index in reachable_defaults():
        key = f"{cls.__name__}.{name}"
        value = cls.__init__.__defaults__[index]
        if key in MODEL_OWNED or not isinstance(value, (bool, int, float, tuple)) or (
                isinstance(value, tuple) and not all(isinstance(v, (int, float)) for v in value)):
            skipped.append(key)
            continue
        changed = list(cls.__init__.__defaults__)
        changed[index] = _perturbed(value)
        with monkeypatch.context() as patch:
            patch.setattr(cls.__init__, "__defaults__", tuple(changed))
            for kind in KINDS:
                assert np.array_equal(_trajectory(load_packaged(kind)), shipped[kind]), (key, kind)
        checked.append(key)
    assert set(skipped) == MODEL_OWNED | NOT_PERTURBED, set(skipped) ^ (MODEL_OWNED | NOT_PERTURBED)
    controller = {f"ControllerConfig.{n}" for n in ("kp", "torque_limit", "touchdown_min_phase", "touchdown_height",
                                                    "min_step_length", "hip_coefficient_range",
                                                    "knee_coefficient_range", "max_kd", "min_phase_rate")}
    rule = {"RecoveryConfig.memory_steps", "RecoveryConfig.ramp_floor", "RecoveryConfig.offsets",
            "OverlayConfig.fast_gate"}
    assert controller | rule <= set(checked)
    with monkeypatch.context() as patch:
        patch.setattr(LegGeometry.__init__, "__defaults__", (0.41, 0.4))
        assert not np.array_equal(_trajectory(load_packaged("classic")), shipped["classic"])


def _spec_copy(tmp_path: Path, kind: str = "learned") -> tuple[Path, dict]:
    """The packaged spec and its weights copied into ``tmp_path``; (path, parsed document)."""
    source = packaged_spec(kind)
    data = yaml.safe_load(source.read_text())
    if data["network"] is not None:
        weights = source.parent / data["network"]["weights"]["file"]
        (tmp_path / weights.name).write_bytes(weights.read_bytes())
    path = tmp_path / source.name
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path, data


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(extra=1), "unknown key 'extra' in spec"),
    (lambda d: d["recovery_rule"].pop("forget_after"), "missing key 'forget_after' in spec.recovery_rule"),
    (lambda d: d["network"].update(activation="relu"), "unknown key 'activation' in spec.network"),
    (lambda d: d["recovery_rule"].update(bins=2.5), "spec.recovery_rule.bins must be a whole number"),
    (lambda d: d["network"].update(hidden=[12, 12]), "the spec's architecture needs"),
    (lambda d: d["network"].update(hidden=[12, 12, 11]), "network layer 2 is (12, 12)"),
    (lambda d: d["network"]["weights"].update(sha256="0" * 64), "the spec names 0000000000000000"),
    (lambda d: d["gait_library"].update(sha256="1" * 64), "the library changed since the spec was written"),
    (lambda d: d.update(spec_version=3), "spec_version 3 is not supported"),
    (lambda d: d.update(spec_version=1), "spec_version 1 names only the controller's blends: upgrade the file with"),
    (lambda d: d["speed_integral"].update(limit=-1.0), "spec.speed_integral: the speed integral's limit must be a finite number > 0, got -1.0"),
    # values checked by meaning, each refusal naming its field
    (lambda d: d["network"]["low"].__setitem__(0, 5.0), "network.low[0] (5.0) must be below network.high[0]"),
    (lambda d: d["network"]["residual"].update(kd_bounds=[150.0, 20.0]),
     "network.residual.kd_bounds must be ordered low < high, got [150.0, 20.0]"),
    (lambda d: d["network"]["input_scale"].__setitem__(1, 0.0), "network.input_scale[1] must be a finite number > 0"),
    (lambda d: d["network"].update(input_offset=[0.0]), "network.input_offset needs 25 numbers (network.inputs), got 1"),
    (lambda d: d["speed_integral"].update(dt=0.5), "speed_integral.dt (0.5 s) must be the time between decisions, "
                                                   "0.02 s (decision.period_ticks 20)"),
    (lambda d: d["speed_integral"].update(speed_range=[1.5, 0.7]), "spec.speed_integral: the speed integral's speed range needs low < high"),
    (lambda d: d["controller"].update(within_step_until=1.5), "spec.controller: within_step_until must be in (0, 1], "
                                                              "got 1.5"),
    (lambda d: d["controller"].update(knee_coefficient_range=[1.9, -0.3]),
     "spec.controller: knee_coefficient_range must be finite and ordered low < high (rad), got [1.9, -0.3]"),
    (lambda d: d["controller"].update(model_sha256="abc"), "controller.model_sha256 must be 64 hex digits"),
    (lambda d: d["blend"].update(length=-0.1), "spec.blend: an alpha blend needs a length and until in"),
    (lambda d: d["gait_library"].update(mode="nearest"), "gait_library.mode 'nearest': a learned controller's gaits"),
    (lambda d: d["network"]["residual"].update(base="raibert"), "network.residual.base must be one of"),
    (lambda d: d["decision"].update(period_ticks=-1), "decision.period_ticks must be a whole number of ticks >= 0"),
    (lambda d: d["decision"].update(window_ticks=0), "decision.window_ticks must be a whole number of ticks >= 1"),
    (lambda d: d.update(overlay=None, blend=None, recovery_rule=None) or d["network"]["residual"].update(
        base="recovery"), "a residual on base recovery needs the recovery_rule it adds to"),
    (lambda d: d["controller"].update(within_step_blend=0.2), "blend: the network's gaits are blended by the overlay"),
])
def test_a_spec_that_cannot_be_built_as_written_fails_with_one_line(tmp_path, edit, message):
    path, data = _spec_copy(tmp_path)
    edit(data)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    with pytest.raises(SpecError) as raised:
        load_controller(path)
    text = str(raised.value)
    assert message in text and "\n" not in text, text


def test_a_weights_file_that_changed_is_refused(tmp_path):
    path, data = _spec_copy(tmp_path)
    weights = tmp_path / data["network"]["weights"]["file"]
    content = bytearray(weights.read_bytes())
    content[-40] ^= 1
    weights.write_bytes(bytes(content))
    with pytest.raises(SpecError, match="network weights .* have sha256"):
        load_controller(path)


def test_the_shipped_specs_name_every_constant_of_the_recovery_rule_and_the_controller():
    """The rule's every field, and the 1 kHz controller's: every ``ControllerConfig`` field but
    the model's geometry and tick, which the model's hash stands for (the names a policy
    announces, ``decision_ticks.CONTROLLER_SETTINGS``)."""
    from rabbit_hzd_controller.controller import ControllerConfig
    from rabbit_msgs_py.decision_ticks import CONTROLLER_SETTINGS
    from rabbit_sim.physics.model import model_sha256

    rule = load_spec(packaged_spec("learned")).recovery_rule
    assert {f for f in RecoveryConfig.__dataclass_fields__} == set(vars(rule))
    assert load_spec(packaged_spec("recovery")).recovery_rule == rule
    controller = set(ControllerConfig.__dataclass_fields__) - {"geometry", "tick"}
    assert set(CONTROLLER_SETTINGS) == controller
    for kind in KINDS:
        spec = load_spec(packaged_spec(kind))
        assert spec.kind == kind and set(spec.controller.settings()) == controller
        assert spec.controller.model_sha256 == model_sha256()


def test_make_policy_builds_the_specs_and_their_variants():
    """Every script builds through the specs: the packaged one, or a variant with its options
    written in; a learned spec file is a policy file; the stack's controller settings are
    the spec's."""
    assert make_policy("learned").spec == load_spec(packaged_spec("learned"))
    assert make_policy("learned", policy_file=packaged_spec("learned")).spec == load_spec(packaged_spec("learned"))
    variant = make_policy("classic", mode="nearest", speed_integral=0.3)
    assert variant.spec.gait_library.mode == "nearest" and variant.spec.speed_integral.gain == 0.3
    assert variant.name == "classic/nearest+integral0.3@20ticks"
    recovery = make_policy("recovery").controller_settings
    assert {k: recovery[k] for k in ("within_step_blend", "within_step_until", "blend_phase")} == {
        "within_step_blend": 0.0, "within_step_until": 1.0, "blend_phase": 0.0}
    with pytest.raises(PolicyUnavailable, match="is a classic controller, not learned"):
        make_policy("learned", policy_file=packaged_spec("classic"))
    with pytest.raises(ValueError, match="the library mode is classic's"):
        make_policy("learned", mode="nearest")  # refused, not ignored
    for kind in ("classic", "recovery"):  # a spec file of any kind runs as its kind
        assert make_policy(kind, policy_file=packaged_spec(kind)).spec == load_spec(packaged_spec(kind))


@pytest.mark.slow
def test_walk_py_runs_a_spec_file_of_any_kind_names_it_and_an_edited_one_walks_its_own_way(tmp_path, capsys):
    """``walk.py --spec FILE``: the controller is the file's kind; the JSON names the file and
    its hash; an edited recovery spec (other offsets) walks differently from the packaged one;
    a --controller that names another kind, or a file that is not a spec, is one line, exit 2."""
    import json

    from rabbit_policy.commands import walk as walk_command
    from rabbit_policy.spec.files import file_sha256

    def run(*args: str) -> tuple[int, dict | str]:
        code = walk_command.main(["--speed", "1.0", "--duration", "4", "--push", "2:-130:0.1", "--json", *args])
        out, err = capsys.readouterr()
        return code, (json.loads(out) if out.strip() else err)

    walks = {}
    for kind in ("classic", "recovery", "learned"):
        code, summary = run("--spec", str(packaged_spec(kind)))
        assert summary["controller"] == kind and summary["spec"] == {
            "file": str(packaged_spec(kind)), "sha256": file_sha256(packaged_spec(kind))}
        walks[kind] = summary
    text = packaged_spec("recovery").read_text().replace("offsets: [-0.11, 0.01, 0.08, -0.23]",
                                                          "offsets: [-0.05, 0.01, 0.04, -0.12]")
    edited = tmp_path / "recovery_edited.yaml"
    edited.write_text(text)
    code, summary = run("--spec", str(edited))
    assert summary["controller"] == "recovery" and summary["spec"]["sha256"] == file_sha256(edited)
    assert summary["touchdowns"] != walks["recovery"]["touchdowns"]  # the rule's offsets moved the walk
    code, err = run("--spec", str(edited), "--controller", "classic")
    assert code == 2 and "is a recovery controller, not classic" in err and len(err.strip().splitlines()) == 1
    code, err = run("--spec", "/nonexistent.yaml")
    assert code == 2 and "/nonexistent.yaml" in err and len(err.strip().splitlines()) == 1


def test_a_spec_is_built_without_torch():
    """policy_node and the loops run a learned spec on numpy alone."""
    code = ("import sys; from rabbit_policy.spec import load_packaged; import rabbit_policy.policy_node; "
            "from rabbit_policy.spec.make import make_policy; p = make_policy('learned'); "
            "from rabbit_policy.runtime.speed_window import Observation; "
            "p.act(Observation(1.0, 1.0, 0.0, (0.0, 0.0, 0.5, 1.0, 1.0))); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "False", out.stderr[-2000:]


def test_the_runtime_has_no_import_circle():
    """recovery.py once imported policies.py inside functions and policies.py recovery.py:
    now the runtime's modules import each other one way only."""
    graph = {}
    for path in (SRC / "runtime").glob("*.py"):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("rabbit_policy.runtime."):
                names.add(node.module.rsplit(".", 1)[1])
        graph[path.stem] = names

    def reaches(start: str, goal: str, seen: set) -> bool:
        return any(n == goal or (n not in seen and reaches(n, goal, seen | {n})) for n in graph.get(start, ()))

    circles = sorted(m for m in graph if reaches(m, m, {m}))
    assert not circles, circles


def test_build_is_the_only_place_a_controller_is_assembled():
    """No module but rabbit_policy.spec.build constructs a network policy or an overlay: the
    loops, the node, the envs, training, evaluation and shipping get theirs from ``build``
    (a training checkpoint through its spec: ``checkpoint_policy``)."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        if path.relative_to(SRC).as_posix() == "spec/build.py":
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id in ("NetworkPolicy", "RecoveryOverlay")):
                found.append(f"{path.relative_to(SRC)}:{node.lineno} {node.func.id}")
    assert not found, found


def test_a_checkpoint_runs_as_its_spec_builds_it_a_residual_on_the_rule_included(tmp_path):
    """A training checkpoint (``.pt``) is converted to its spec in memory and built; its spec,
    written to a file, builds the same controller (the residual on the recovery rule, which a
    spec now names, included)."""
    from rabbit_policy.runtime.network import PolicyCheckpoint
    from rabbit_policy.spec import dump_spec
    from rabbit_policy.spec.convert import learned_spec
    from test_recovery_overlay import _zero_residual_on_recovery_file

    for base in ("recovery", "recovery_gated"):
        pt = tmp_path / f"{base}.pt"
        _zero_residual_on_recovery_file(pt, base=base, scale_weights=0.3)
        policy = checkpoint_policy(pt)
        assert policy.spec.network.residual.base == base and policy.spec.recovery_rule is not None
        spec = learned_spec(PolicyCheckpoint.load(pt), tmp_path, name=base)
        dump_spec(spec, tmp_path / f"{base}.yaml")
        written = load_controller(tmp_path / f"{base}.yaml")
        assert np.array_equal(_trajectory(written), _trajectory(policy))


def test_a_spec_round_trips_through_its_file(tmp_path):
    from rabbit_policy.spec import dump_spec

    spec = load_spec(packaged_spec("learned"))
    dump_spec(replace(spec, name="copy"), tmp_path / "copy.yaml", "a copy")
    assert load_spec(tmp_path / "copy.yaml") == replace(spec, name="copy")
    assert build(spec, packaged_spec("learned").parent).spec == spec


def test_a_rules_section_is_its_runtime_class_read_strictly():
    """A spec's ``speed_integral``, ``recovery_rule`` and ``overlay`` are the runtime's
    ``IntegralConfig``, ``RecoveryConfig`` and ``OverlayConfig`` themselves (no mirror class, no
    translator), read by the spec's strict
    loader: a key missing is refused although the class has a code default for it, except the
    windup decay's ``disturbance`` (its ``OPTIONAL_KEYS``); an unknown key or a bad value is one line."""
    from rabbit_policy.runtime.recovery import OverlayConfig, RecoveryConfig
    from rabbit_policy.runtime.speed_integral import IntegralConfig, WindupDecay

    shipped = load_spec(packaged_spec("learned"))
    assert type(shipped.speed_integral) is IntegralConfig and type(shipped.recovery_rule) is RecoveryConfig
    assert type(shipped.speed_integral.windup_decay) is WindupDecay and type(shipped.overlay) is OverlayConfig
    data = shipped.to_dict()
    for section, key in (("speed_integral", "gain"), ("recovery_rule", "bins"), ("overlay", "rise_until")):
        broken = {**data, section: {k: v for k, v in data[section].items() if k != key}}
        with pytest.raises(SpecError, match=f"missing key '{key}' in spec.{section}"):
            parse_spec(broken)
    decay = {k: v for k, v in data["speed_integral"]["windup_decay"].items() if k != "disturbance"}
    assert parse_spec({**data, "speed_integral": {**data["speed_integral"], "windup_decay": decay}}
                      ).speed_integral.windup_decay.disturbance is None
    with pytest.raises(SpecError, match="unknown key 'gian' in spec.speed_integral"):
        parse_spec({**data, "speed_integral": {**data["speed_integral"], "gian": 1.0}})
    with pytest.raises(SpecError, match="spec.speed_integral: the speed integral's gain must be a finite number >= 0"):
        parse_spec({**data, "speed_integral": {**data["speed_integral"], "gain": -1.0}})


def test_the_learned_spec_env_is_the_deployed_loop_with_the_network_as_the_agent():
    """``RabbitHZD-Learned-v1``: an agent that gives the network's own outputs walks the
    deployed controller's walk bit for bit (the same scenario: a push the rule answers, a
    speed change, a forward push), every rule of the spec acting."""
    import gymnasium as gym

    env = gym.make("RabbitHZD-Learned-v1", max_steps=350)
    obs, _ = env.reset(seed=0, options={"scenario": SCENARIO})
    network = load_packaged("learned").forward
    steps, truncated = 0, False
    while not truncated:
        obs, _reward, terminated, truncated, info = env.step(network.normalised(obs))
        steps += 1
        assert not terminated and not info["rejected"]
    trained_on = env.unwrapped.loop.result()
    deployed = walk(load_packaged("learned"), SCENARIO, 7.0)
    assert steps == 350 and np.array_equal(trained_on.hip_x, deployed.hip_x)
    assert env.unwrapped.policy.spec == load_spec(packaged_spec("learned"))


def test_the_learned_spec_env_passes_gymnasiums_checker():
    import gymnasium as gym
    from gymnasium.utils.env_checker import check_env

    env = gym.make("RabbitHZD-Learned-v1", max_steps=5)
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=1)
    assert env.observation_space.contains(obs) and env.action_space.shape == (21,)
    with pytest.raises(ValueError, match="decides every N ticks"):
        from rabbit_policy.learning.spec_env import SpecEnv

        SpecEnv(spec=packaged_spec("classic"))


@pytest.mark.slow
def test_train_es_on_a_spec_trains_its_network_in_its_deployed_loop_and_writes_a_spec(tmp_path):
    """``train.py --spec``: ES starts from the spec's network, runs its episodes in the spec's
    deployed loop (RabbitHZD-Learned-v1) and writes the policy as the spec with the trained
    weights, which walk.py runs; PPO is refused with one line."""
    root = Path(__file__).resolve().parents[2]
    spec = packaged_spec("learned")
    common = [sys.executable, "scripts/train.py", "--algo", "es", "--spec", str(spec), "--seed", "1", "--workers",
              "1", "--pairs", "1", "--episodes", "1", "--max-steps", "5", "--no-progress", "--distribution",
              "paper", "--iterations", "1", "--eval-every", "0", "--sigma", "0.02"]
    run = subprocess.run([*common, "--out", str(tmp_path / "run")], cwd=root, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-3000:]
    trained = load_spec(tmp_path / "run" / "policy.yaml")
    shipped = load_spec(spec)
    assert trained.network.weights.sha256 != shipped.network.weights.sha256  # one generation moved them
    assert replace(trained, network=replace(trained.network, weights=shipped.network.weights),
                   provenance=shipped.provenance) == shipped  # every other stage and constant as the spec's
    policy = make_policy("learned", policy_file=tmp_path / "run" / "policy.yaml")
    assert not walk(policy, Scenario.constant(1.0), 3.0).failed
    with pytest.raises(PolicyUnavailable, match="its policy is policy.yaml"):
        make_policy("learned", policy_file=tmp_path / "run" / "policy.pt")
    walked = subprocess.run([sys.executable, "scripts/walk.py", "--controller", "learned", "--policy-file",
                             str(tmp_path / "run" / "policy.yaml"), "--duration", "2", "--json"], cwd=root,
                            capture_output=True, text=True, timeout=300)
    assert walked.returncode == 0, walked.stderr[-2000:]
    refused = subprocess.run([sys.executable, "scripts/train.py", "--algo", "ppo", "--spec", str(spec), "--out",
                              str(tmp_path / "ppo"), "--no-progress"], cwd=root, capture_output=True, text=True,
                             timeout=300)
    assert refused.returncode == 2 and refused.stderr.strip().splitlines()[-1].startswith("error: --spec trains with ES")


def test_the_packaged_specs_were_written_from_a_clean_commit_of_this_history():
    """A dirty tree is not a provenance: each packaged spec names a commit (no ``+dirty``),
    one this repository holds."""
    root = Path(__file__).resolve().parents[2]
    for kind in KINDS:
        commit = load_spec(packaged_spec(kind)).provenance["code_commit"]
        assert len(commit) == 40 and all(c in "0123456789abcdef" for c in commit), (kind, commit)
        if (root / ".git").exists():
            known = subprocess.run(["git", "cat-file", "-e", f"{commit}^{{commit}}"], cwd=root, capture_output=True)
            assert known.returncode == 0, (kind, commit)


def test_a_version_1_spec_is_refused_with_its_upgrade_and_upgrades_to_the_same_controller(tmp_path):
    """Version 1 named the controller's blends alone: refused with one line naming
    ``upgrade_spec``, which completes it with the values version 1 ran with: the packaged
    specs, written back as version 1, upgrade to themselves (their provenance aside)."""
    from rabbit_policy.spec.convert import upgrade_spec

    for kind in KINDS:
        path, data = _spec_copy(tmp_path, kind)
        data["spec_version"] = 1
        data["controller"] = {k: data["controller"][k] for k in ("within_step_blend", "within_step_until",
                                                                 "blend_phase")}
        path.write_text("# an old run's spec\n" + yaml.safe_dump(data, sort_keys=False))
        with pytest.raises(SpecError, match="spec_version 1 names only the controller's blends"):
            load_spec(path)
        upgraded = upgrade_spec(path)
        packaged = load_spec(packaged_spec(kind))
        assert replace(upgraded, provenance={}) == replace(packaged, provenance={}), kind
        assert load_spec(path) == upgraded and path.read_text().startswith("# an old run's spec\n")


def test_a_start_calibrated_to_itself_carries_its_own_steady_integrals(tmp_path):
    """calibrate_spec re-measures a learned spec's feed-forward table on that spec's own
    controller (the start reproduce.py's ``start: calibrated`` trains from), keeping the
    speeds, the ``start`` flag and everything else."""
    from rabbit_policy.evaluation.steady_integral import calibrate_spec, steady_integrals

    path, data = _spec_copy(tmp_path)
    data["speed_integral"]["feedforward"].update(speeds=[0.8, 1.1, 1.4], values=[0.3, -0.3, 0.3])
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    before = load_spec(path)
    written = calibrate_spec(path)
    assert load_spec(path) == written and "re-measured" in written.provenance["feedforward"]
    table = written.speed_integral.feedforward
    assert table.speeds == (0.8, 1.1, 1.4) and table.start == before.speed_integral.feedforward.start
    assert table.values == steady_integrals(load_controller(path), table.speeds).values
    assert max(abs(v) for v in table.values) < 0.1  # the zero residual's own integral stays near 0
    assert written.network == before.network and written.recovery_rule == before.recovery_rule


def test_a_spec_that_is_not_yaml_is_one_line_naming_where(tmp_path):
    """A YAML syntax error in a spec: one line with the line and column (from 1) and what is wrong."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("spec_version: 2\nname: x\nkind: [learned\n")
    with pytest.raises(SpecError) as refused:
        load_spec(bad)
    text = str(refused.value)
    assert "\n" not in text and "is not YAML: line 4, column 1: expected ',' or ']'" in text
