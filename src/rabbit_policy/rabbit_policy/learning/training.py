"""The HZD-RL training loop behind ``scripts/train.py``: warm start, ES or PPO iterations,
acceptance evaluations, checkpoints, ``--resume`` and clean interruption
(:func:`train` with a :class:`TrainingConfig`).

Both start from the same network warm-started on the classic gait library
(``rabbit_policy.learning.warm_start``, 5-15 s: ``--warm-start feedback``, the default, or
``scheduled``, ``nearest``, ``interpolate``; ``none`` starts from random weights). ES: ``rabbit_policy.learning.es`` (antithetic pairs, centred ranks, Adam; one iteration =
one generation; ``--workers`` processes evaluate the population). PPO:
``rabbit_policy.learning.ppo`` (CleanRL-style clipped objective, GAE; one iteration = one rollout
of ``--envs`` environments x ``--steps`` steps + update; ``--envs`` processes).

Outputs in OUT:
* ``log.csv``: one row per iteration (wall time, env steps, returns, fall fraction, mean
  |v̄ - v_d| per step, algorithm statistics); a progress bar on the terminal.
* ``tb/``: TensorBoard scalars of both (``rabbit_policy.learning.scalars``: the tags the SB3
  baseline writes too); ``scripts/plot_training.py OUT`` draws the curves to PNG.
* ``eval.csv``: every ``--eval-every`` iterations the current deterministic policy runs
  the acceptance checks (``rabbit_policy.evaluation.acceptance``: 9 constant speeds x 30 s and the
  0.8 -> 1.2 -> 0.9 -> 1.5 -> 0.7 m/s schedule, ROS-free); failures and errors per row.
* ``policy.pt``: the latest policy; ``best.pt``: the trained policy (iteration >= 1; the
  warm start is evaluated at iteration 0 as a baseline only) that did best on the
  acceptance checks so far (fewest failed checks, then smallest summed error);
  ``checkpoint.pt``: everything needed to ``--resume`` (written every
  ``--checkpoint-every`` iterations, at the end, on Ctrl-C and on SIGTERM — then the
  worker processes are killed); ``summary.json``: when a trained policy (iteration >= 1)
  first passed the acceptance (iteration, wall time, env steps), the best result, and
  whether the warm start alone passed.
``evaluated/ITERATION.pt`` (with ``--keep-evaluated``): every evaluated policy, to choose
among them afterwards on checks the acceptance does not run (the tracking acceptance alone
picked policies that lost random sequences and push margin, docs/learning.md).
``--stop-when-passed`` ends training at the first passing evaluation of a trained policy.
Deterministic for a given seed and worker count (ES: exactly, also across --resume; PPO:
a resumed run starts fresh episodes).
"""

from __future__ import annotations

import csv
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any
from multiprocessing import active_children
from pathlib import Path

import torch
from tqdm import tqdm

from rabbit_msgs_py import strict_json
from rabbit_msgs_py.cli import option, positive_int, run_dir_problem
from rabbit_policy.evaluation.acceptance import acceptance, acceptance_rank
from rabbit_policy.spec.provenance import provenance
from rabbit_policy.learning.es import EvolutionStrategy
from rabbit_policy.learning.ppo import PPOTrainer
from rabbit_policy.learning.scalars import TrainingScalars
from rabbit_policy.learning.warm_start import initial_network, zero_residual_network
from rabbit_policy.parallel import BackendConfig, BackendUnavailable, make_backend
from rabbit_policy.runtime.actions import (RESIDUAL_SCALE, ActionBounds, ResidualAction, policy_bounds,
                                           residual_sum_bounds)
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.memory import INPUTS
from rabbit_policy.runtime.network import (NetworkForward, PolicyCheckpoint, parameter_count, spec_network,
                                           widen_inputs)
from rabbit_policy.spec import build, load_controller, load_spec
from rabbit_policy.learning.trained_specs import trained_spec
from rabbit_policy.spec.files import file_sha256
from rabbit_policy.spec.make import policy_of_checkpoint


@dataclass(frozen=True)
class TrainingConfig:
    """One training run: ``scripts/train.py`` builds its command line from these fields (and
    from the trainer's: an :class:`~.es.ESConfig` or a :class:`~.ppo.PPOConfig`, whose
    ``seed`` and ``max_steps`` are the run's). The defaults are the first shipped policy's run (config/train/first_shipped_es.yaml)."""

    algo: str
    out: Path
    trainer: Any
    workers: int = option(2, "processes (or Ray CPUs) for rollouts and evaluations", type=positive_int)
    iterations: int = option(30, "ES generations / PPO iterations in all, resumed ones included",
                             aliases=("--generations",))
    checkpoint_every: int = option(5, "write checkpoint.pt every N iterations (and on Ctrl-C/SIGTERM)")
    eval_every: int = option(5, "acceptance evaluation every N iterations, and of the start (0: never)")
    stop_when_passed: bool = option(False, "stop at the first trained policy that passes the evaluation")
    validate_recovery: bool = option(False, "the evaluation also pushes (0.7/1.0/1.3 m/s, 4 phases, backward 1.5x "
                                            "and forward 1x classic's margin) and checks settling within 0.03 m/s, "
                                            "so best.pt is picked on recovery too (rabbit_policy.evaluation."
                                            "acceptance)")
    keep_evaluated: bool = option(False, "also save every evaluated policy as OUT/evaluated/ITERATION.pt, to "
                                         "choose among them later on broader checks (compare_policies.py)")
    warm_start: str = option("feedback", "fit the network to the classic library first "
                                         "(rabbit_policy.learning.warm_start; none: random weights)",
                             choices=("scheduled", "nearest", "interpolate", "feedback", "none"))
    no_progress: bool = option(False, "plain lines instead of a progress bar")
    resume: bool = option(False, "continue from OUT/checkpoint.pt (give the same options)")
    backend: BackendConfig = BackendConfig()

    def __post_init__(self) -> None:
        if self.algo not in ("es", "ppo"):
            raise ValueError(f"algo must be es or ppo, got {self.algo!r}")
        if min(self.workers, self.iterations, self.checkpoint_every) < 1:
            raise ValueError("workers, iterations and checkpoint_every must be >= 1")
        if self.eval_every < 0:
            raise ValueError("eval_every must be >= 0")

    @property
    def seed(self) -> int:
        return self.trainer.seed


SPEC_DECIDES = ("features", "action", "residual_base", "integral_gain", "integral_band", "integral_clip",
                "integral_windup_decay", "decision_period")
"""Episode options a ``--spec`` run takes from the spec instead (left out of its record)."""


def make_trainer(args: TrainingConfig, net, backend=None):
    """The ES or PPO trainer for the configured algorithm, running its episodes on ``backend``."""
    if args.algo == "es":

        return EvolutionStrategy(net, args.trainer, backend)

    return PPOTrainer(net, args.trainer, backend)


def evaluation_row(iteration: int, wall: float, env_steps: int, result: dict) -> dict:
    """One ``eval.csv`` row from an acceptance result."""
    errors = [abs(c["error"]) for c in result["constant"] if c["error"] is not None]
    reaches = [s["reach_time"] for s in result["schedule"]["segments"][1:]]
    return {"iteration": iteration, "wall_s": round(wall, 1), "env_steps": env_steps, "passed": result["passed"],
            "failures": result["failures"], "total_error": round(result["total_error"], 4),
            "worst_speed_error": round(max(errors), 4) if errors else None,
            "falls": sum(c["fell"] for c in result["constant"]) + int(result["schedule"]["fell"]),
            "slowest_reach_s": None if not reaches or None in reaches else round(max(reaches), 2)}


def _refusal(args: TrainingConfig) -> str | None:
    """Why ``args`` cannot run (an unusable --out or --resume, --spec with PPO), else None."""
    problem = run_dir_problem(args.out, args.resume, "checkpoint.pt")
    if problem:
        return problem
    if getattr(args.trainer, "spec", "") and args.algo != "es":
        return ("--spec trains with ES (the spec's network in its deployed loop); PPO's sampler and critic are "
                "not wired to it")
    return None


@dataclass
class Start:
    """The network a run trains and what it is: its action bounds, inputs (``features``), action
    kind, memory and residual, and for a ``--spec`` run the spec's deployed controller."""

    net: Any
    bounds: ActionBounds
    features: str
    action: str
    memory: Any = None
    residual: ResidualAction | None = None
    deployed: Any = None
    spec_sha256: str = ""
    mse: float | None = None


def starting_network(args: TrainingConfig, library: GaitLibrary) -> Start:
    """The network training starts from: the spec's (``--spec``), the zero residual (action
    residual), or the warm start on the library (none on ``--resume``: the checkpoint's weights
    replace it); the messages saying which are printed here."""
    trainer = args.trainer
    features, action = trainer.features, trainer.action
    bounds = policy_bounds(action, library)
    memory = trainer.memory_config(library.speed_range)
    residual = (ResidualAction(library, residual_sum_bounds(library, trainer.residual_base),
                               integral_gain=trainer.integral_gain) if action == "residual" else None)
    spec_file = getattr(trainer, "spec", "")
    if spec_file:  # the spec's network, in the spec's deployed loop (RabbitHZD-Learned-v1)
        deployed = load_controller(spec_file)
        net = spec_network(deployed.forward)
        if not args.resume:
            print(f"spec {spec_file}: starts from its network, in its deployed loop", flush=True)
        return Start(net, ActionBounds(net.low.numpy().astype(float), net.high.numpy().astype(float)),
                     deployed.spec.network.features, "spec", deployed=deployed, spec_sha256=file_sha256(spec_file))
    if residual is not None:  # a zero residual: the classic controller (or the residual's base)
        if args.warm_start != "none" and not args.resume:
            print(f"action residual: starts from the zero residual (classic HZD); --warm-start {args.warm_start} "
                  "is not used", flush=True)
        return Start(zero_residual_network(bounds.low, bounds.high, INPUTS[features], args.seed), bounds, features,
                     action, memory, residual)
    net, mse = initial_network(bounds.low, bounds.high, library, args.seed, "none" if args.resume else args.warm_start)
    if memory is not None:  # the warm start on the paper's three, the memory inputs at zero weight
        net = widen_inputs(net, INPUTS[features], memory.integral.limit)
    return Start(net, bounds, features, action, memory, residual, mse=mse)


class TrainingRun:
    """One run of :func:`train`: the trainer on the start's network, and what it writes to OUT
    (the module docstring). ``state``: a checkpoint's (``--resume``), else empty."""

    def __init__(self, args: TrainingConfig, start: Start, trainer, backend, state: dict) -> None:
        self.args, self.start, self.net, self.trainer, self.backend = args, start, start.net, trainer, backend
        self.out = args.out
        self.spec_file = getattr(args.trainer, "spec", "")
        self.began = time.perf_counter()  # wall time includes the warm start and the evaluations
        self.elapsed_before = state.get("wall_s", 0.0)
        self.ran_on = provenance()  # the code and the machine's numerics, recorded with every checkpoint
        self.best = state.get("best")  # {"rank": [...], "iteration": ..., ...}
        self.warm_start_result: dict = state.get("warm_start", {})  # its acceptance at iteration 0, if evaluated
        self.first_pass = state.get("first_pass")
        self.config = args.trainer.to_dict()
        if self.spec_file:  # what the spec decides, not the options (which its deployed loop does not read)
            for key in SPEC_DECIDES:
                self.config.pop(key, None)
        self.scalars = TrainingScalars(self.out / "tb", args.algo)
        self.bar = tqdm(total=args.iterations, initial=trainer.iteration, unit="it", disable=args.no_progress,
                        dynamic_ncols=True)
        if args.no_progress:
            self.bar.write = print  # type: ignore[method-assign]

    def wall(self) -> float:
        return self.elapsed_before + time.perf_counter() - self.began

    def info(self, extra: dict | None = None) -> dict:
        """The run's record, saved with every policy."""
        args, start, trainer = self.args, self.start, self.trainer
        return {"algorithm": args.algo, "seed": args.seed, "workers": args.workers, "iteration": trainer.iteration,
                "env_steps": trainer.env_steps, "wall_s": round(self.wall(), 1), "config": self.config,
                "warm_start": "none: the spec's network" if self.spec_file else args.warm_start,
                "eval_every": args.eval_every,
                "parameters": parameter_count(self.net), "features": start.features, "action": start.action,
                "output": self.net.output,
                **({"memory": start.memory.to_dict()} if start.memory is not None else {}),
                **({"residual_scale": list(RESIDUAL_SCALE), "integral_gain": args.trainer.integral_gain,
                    "residual_base": args.trainer.residual_base} if start.residual is not None else {}),
                **({"spec": str(Path(self.spec_file).resolve()), "spec_sha256": start.spec_sha256,
                    "decision_period": start.deployed.spec.decision.period_ticks} if self.spec_file else {}),
                "provenance": self.ran_on, **(extra or {})}

    def save_policy(self, name: str, extra: dict | None = None) -> None:
        """OUT/NAME.pt, and for a spec's run OUT/NAME.yaml: the spec with these weights."""
        bounds = self.start.bounds
        PolicyCheckpoint(self.net.state_dict(), bounds.low, bounds.high, self.info(extra)).save(self.out / f"{name}.pt")
        if self.spec_file:
            trained_spec(self.spec_file, self.net, self.out / f"{name}.yaml",
                         {"trained_by": "scripts/train.py --spec", "iteration": self.trainer.iteration,
                          "env_steps": self.trainer.env_steps, "seed": self.args.seed})

    def save_checkpoint(self) -> None:
        torch.save({"algo": self.args.algo, "net": self.net.state_dict(), "trainer": self.trainer.state_dict(),
                    "wall_s": self.wall(), "best": self.best, "first_pass": self.first_pass,
                    "warm_start": self.warm_start_result}, self.out / "checkpoint.pt")
        self.save_policy("policy")
        (self.out / "summary.json").write_text(strict_json.dumps(
            {"info": self.info(), "first_pass": self.first_pass, "best": self.best,
             "warm_start": self.warm_start_result}, indent=2) + "\n")

    def policy_now(self):
        """The deterministic policy of the weights now, as it is deployed."""
        trainer = self.trainer
        if self.spec_file:  # the deployed controller with the weights now
            forward = NetworkForward.of(self.net)
            return build(load_spec(self.spec_file), Path(self.spec_file).resolve().parent,
                         weights=(list(forward.weights), list(forward.biases)),
                         source=f"{Path(self.spec_file).name}@{trainer.iteration}")
        bounds = self.start.bounds
        return policy_of_checkpoint(PolicyCheckpoint(self.net.state_dict(), bounds.low, bounds.high, self.info()),
                                    f"{self.out.name}@{trainer.iteration}")

    def evaluate(self) -> None:
        """The acceptance checks of the policy now: eval.csv, best.pt, evaluated/ (the module docstring)."""
        trainer = self.trainer
        result = acceptance(self.policy_now(), map_fn=self.backend.map, recovery=self.args.validate_recovery)
        row = evaluation_row(trainer.iteration, self.wall(), trainer.env_steps, result)
        append_csv(self.out / "eval.csv", row)
        self.scalars.evaluation(row)
        baseline = trainer.iteration == 0  # the warm start: logged, not a trained policy
        if baseline:
            self.warm_start_result["passed"] = result["passed"]
            self.warm_start_result["failures"] = result["failures"]
        elif result["passed"] and self.first_pass is None:
            self.first_pass = {k: row[k] for k in ("iteration", "wall_s", "env_steps")}
        if not baseline and (self.best is None or list(acceptance_rank(result)) < self.best["rank"]):
            self.best = {**row, "rank": list(acceptance_rank(result))}
            self.save_policy("best", {"acceptance": result})
        if self.args.keep_evaluated:
            (self.out / "evaluated").mkdir(exist_ok=True)
            self.save_policy(f"evaluated/{trainer.iteration:05d}", {"acceptance": result})
        self.bar.write(f"  acceptance @ {trainer.iteration}: {'PASSED' if result['passed'] else 'failed'} "
                       f"({row['failures']} failed checks, worst speed error {row['worst_speed_error']}, "
                       f"slowest reach {row['slowest_reach_s']} s)")

    def iterate(self) -> None:
        """One iteration: log.csv, the progress line, and the evaluation and checkpoint when due."""
        args, trainer = self.args, self.trainer
        stats = trainer.step()
        append_csv(self.out / "log.csv", {"wall_s": round(self.wall(), 1), **stats})
        self.scalars.iteration(stats, self.wall())
        self.bar.update(1)
        self.bar.set_postfix(ret=f"{stats['episode_return']:.3f}", err=f"{stats['mean_abs_error']:.3f}",
                             falls=f"{stats['fall_fraction']:.2f}")
        if args.no_progress:
            print(strict_json.dumps(stats), flush=True)
        if args.eval_every and trainer.iteration % args.eval_every == 0:
            self.evaluate()
        if trainer.iteration % args.checkpoint_every == 0:
            self.save_checkpoint()

    def run(self) -> bool:
        """Iterate to ``iterations`` (or the first pass with ``stop_when_passed``); returns
        whether it was interrupted (Ctrl-C, SIGTERM: a checkpoint is written either way)."""
        args, trainer = self.args, self.trainer
        interrupted = False
        try:
            if args.eval_every and trainer.iteration == 0:
                self.evaluate()  # the starting point (warm start) as a baseline
            while trainer.iteration < args.iterations:
                self.iterate()
                if args.stop_when_passed and self.first_pass is not None and args.eval_every \
                        and trainer.iteration % args.eval_every == 0:
                    break
        except KeyboardInterrupt:
            interrupted = True
            self.bar.write("interrupted: saving a checkpoint")
        finally:
            self.bar.close()
            self.scalars.close()
            self.save_checkpoint()
            if not interrupted:
                trainer.close()
                self.backend.close()
        best = self.best
        print(strict_json.dumps({"out": str(self.out), "iteration": trainer.iteration, "env_steps": trainer.env_steps,
                                 "wall_s": round(self.wall(), 1), "first_pass": self.first_pass,
                                 "best": None if best is None else {k: best[k] for k in ("iteration", "failures",
                                                                                         "total_error")}}))
        return interrupted


def train(args: TrainingConfig) -> int:
    """Run training as configured (setup, the loop, evaluations, checkpoints: :class:`TrainingRun`);
    returns the exit status (0, or 2 for an unusable --out/--resume or backend; interrupted by
    Ctrl-C or SIGTERM it leaves with 128 + the signal once its checkpoint is written)."""
    problem = _refusal(args)
    if problem:
        print(f"error: {problem}", file=sys.stderr)
        return 2
    try:  # before anything slow: a backend that cannot start is a one-line error at once
        backend = make_backend(args.backend)
    except BackendUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    began = time.perf_counter()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    args.out.mkdir(parents=True, exist_ok=True)
    start = starting_network(args, GaitLibrary.load())
    state: dict = {}
    if args.resume:
        checkpoint_path = args.out / "checkpoint.pt"
        state = torch.load(checkpoint_path, map_location="cpu", weights_only=False)
        if state["algo"] != args.algo:
            print(f"error: {checkpoint_path} is an {state['algo']} run, not {args.algo}", file=sys.stderr)
            backend.close()
            return 2
        start.net.load_state_dict(state["net"])
    elif start.mse is not None:
        print(f"warm start ({args.warm_start}) on the classic gait library: mse {start.mse:.2e} "
              "(normalised action units)", flush=True)
    trainer = make_trainer(args, start.net, backend)
    if state:
        trainer.load_state_dict(state["trainer"])
    run = TrainingRun(args, start, trainer, backend, state)
    run.began = began  # the warm start counts in the run's wall time

    received = [signal.SIGINT]  # Ctrl-C raises KeyboardInterrupt itself

    def interrupt(signum, _frame):
        received[0] = signum
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)  # SIGTERM saves a checkpoint like Ctrl-C
    if run.run():
        stop_workers(trainer, backend, 128 + received[0])
    return 0


def stop_workers(trainer, backend, status: int) -> None:
    """After Ctrl-C/SIGTERM, with the checkpoint written: stop the pools (which also stops
    them from starting replacement workers), kill and reap whatever worker is left, and
    leave without multiprocessing's exit handlers, with exit ``status`` (128 + the signal, the
    shell's convention: an interrupted training is not a finished one, ``--resume`` continues it).
    ``Pool.terminate()`` can block on a
    queue lock held by an interrupted worker (runs hung after ``pkill -f train.py``, which
    signals the workers too), so it gets a few seconds in a thread and the kill does not
    depend on it."""
    def terminate() -> None:
        for close in (trainer.close, backend.close):  # a private Ray instance is shut down with the backend
            try:
                close(terminate=True)
            except (OSError, EOFError):  # workers signalled too (pkill -f): their pipes are already closed
                pass

    stopper = threading.Thread(target=terminate, daemon=True)
    stopper.start()
    stopper.join(timeout=5.0)
    for _ in range(2):  # a second pass for a replacement started meanwhile
        children = active_children()
        for child in children:
            child.kill()
        for child in children:
            child.join(timeout=5.0)  # reap: no zombies left behind
        time.sleep(0.2)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def append_csv(path: Path, row: dict) -> None:
    """Append ``row``; write the header first if the file is new."""
    new = not path.exists()
    with path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(row))
        if new:
            writer.writeheader()
        writer.writerow(row)
