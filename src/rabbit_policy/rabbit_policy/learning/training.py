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
from rabbit_msgs_py.cli import option, positive_int
from rabbit_policy.evaluation.acceptance import acceptance, acceptance_rank
from rabbit_policy.experiment.provenance import provenance
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
from rabbit_policy.spec.convert import trained_spec
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


def train(args: TrainingConfig) -> int:
    """Run training as configured; returns the exit status (0, or 2 for an unusable --out/--resume)."""
    out: Path = args.out
    if out.exists() and not args.resume and any(out.iterdir()):
        print(f"error: {out} is not empty; use --resume or another --out", file=sys.stderr)
        return 2
    checkpoint_path = out / "checkpoint.pt"
    if args.resume and not checkpoint_path.is_file():
        print(f"error: --resume: no {checkpoint_path}", file=sys.stderr)
        return 2

    if getattr(args.trainer, "spec", "") and args.algo != "es":
        print("error: --spec trains with ES (the spec's network in its deployed loop); PPO's sampler and critic "
              "are not wired to it", file=sys.stderr)
        return 2
    try:  # before anything slow: a backend that cannot start is a one-line error at once
        backend = make_backend(args.backend)
    except BackendUnavailable as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    start = time.perf_counter()  # wall time includes the warm start and the evaluations
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    out.mkdir(parents=True, exist_ok=True)
    library = GaitLibrary.load()
    features, action = args.trainer.features, args.trainer.action
    bounds = policy_bounds(action, library)
    gain = args.trainer.integral_gain
    memory = args.trainer.memory_config(library.speed_range)
    residual = (ResidualAction(library, residual_sum_bounds(library, args.trainer.residual_base), integral_gain=gain)
                if action == "residual" else None)
    spec_file = getattr(args.trainer, "spec", "")
    if spec_file:  # the spec's network, in the spec's deployed loop (RabbitHZD-Learned-v1)

        deployed = load_controller(spec_file)
        spec_sha256 = file_sha256(spec_file)
        net, mse = spec_network(deployed.forward), None
        bounds = ActionBounds(net.low.numpy().astype(float), net.high.numpy().astype(float))
        features, action = deployed.spec.network.features, "spec"
        memory, residual = None, None
        if not args.resume:
            print(f"spec {spec_file}: starts from its network, in its deployed loop", flush=True)
    elif residual is not None:  # a zero residual: the classic controller (or the residual's base)
        net, mse = zero_residual_network(bounds.low, bounds.high, INPUTS[features], args.seed), None
        if args.warm_start != "none" and not args.resume:
            print(f"action residual: starts from the zero residual (classic HZD); --warm-start {args.warm_start} "
                  "is not used", flush=True)
    else:
        net, mse = initial_network(bounds.low, bounds.high, library, args.seed,
                                   "none" if args.resume else args.warm_start)
        if memory is not None:  # the warm start on the paper's three, the memory inputs at zero weight
            net = widen_inputs(net, INPUTS[features], memory.integral.limit)
    state: dict = {}
    if args.resume:
        state = torch.load(checkpoint_path, map_location="cpu", weights_only=False)
        if state["algo"] != args.algo:
            print(f"error: {checkpoint_path} is an {state['algo']} run, not {args.algo}", file=sys.stderr)
            backend.close()
            return 2
        net.load_state_dict(state["net"])
    elif mse is not None:
        print(f"warm start ({args.warm_start}) on the classic gait library: mse {mse:.2e} "
              "(normalised action units)", flush=True)
    trainer = make_trainer(args, net, backend)
    if state:
        trainer.load_state_dict(state["trainer"])
    elapsed_before = state.get("wall_s", 0.0)
    ran_on = provenance()  # the code and the machine's numerics, recorded with every checkpoint
    best = state.get("best")  # {"rank": [...], "iteration": ..., ...}
    warm_start_result: dict = state.get("warm_start", {})  # its acceptance at iteration 0, if evaluated
    first_pass = state.get("first_pass")

    def wall() -> float:
        return elapsed_before + time.perf_counter() - start

    config = args.trainer.to_dict()
    if spec_file:  # what the spec decides, not the options (which its deployed loop does not read)
        for key in SPEC_DECIDES:
            config.pop(key, None)

    def info(extra: dict | None = None) -> dict:
        return {"algorithm": args.algo, "seed": args.seed, "workers": args.workers, "iteration": trainer.iteration,
                "env_steps": trainer.env_steps, "wall_s": round(wall(), 1), "config": config,
                "warm_start": "none: the spec's network" if spec_file else args.warm_start,
                "eval_every": args.eval_every,
                "parameters": parameter_count(net), "features": features, "action": action, "output": net.output,
                **({"memory": memory.to_dict()} if memory is not None else {}),
                **({"residual_scale": list(RESIDUAL_SCALE), "integral_gain": gain,
                    "residual_base": args.trainer.residual_base} if residual is not None else {}),
                **({"spec": str(Path(spec_file).resolve()), "spec_sha256": spec_sha256,
                    "decision_period": deployed.spec.decision.period_ticks} if spec_file else {}),
                "provenance": ran_on, **(extra or {})}

    def save_policy(name: str, extra: dict | None = None) -> None:
        """OUT/NAME.pt, and for a spec's run OUT/NAME.yaml: the spec with these weights."""
        PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high, info(extra)).save(out / f"{name}.pt")
        if spec_file:

            trained_spec(spec_file, net, out / f"{name}.yaml", {"trained_by": "scripts/train.py --spec",
                                                               "iteration": trainer.iteration,
                                                               "env_steps": trainer.env_steps, "seed": args.seed})

    def save_checkpoint() -> None:
        torch.save({"algo": args.algo, "net": net.state_dict(), "trainer": trainer.state_dict(), "wall_s": wall(),
                    "best": best, "first_pass": first_pass, "warm_start": warm_start_result}, checkpoint_path)
        save_policy("policy")
        (out / "summary.json").write_text(strict_json.dumps({"info": info(), "first_pass": first_pass, "best": best,
                                                      "warm_start": warm_start_result}, indent=2) + "\n")

    scalars = TrainingScalars(out / "tb", args.algo)

    def evaluate() -> None:
        nonlocal best, first_pass
        if spec_file:  # the deployed controller with the weights now

            forward = NetworkForward.of(net)
            policy = build(load_spec(spec_file), Path(spec_file).resolve().parent,
                           weights=(list(forward.weights), list(forward.biases)),
                           source=f"{Path(spec_file).name}@{trainer.iteration}")
        else:
            policy = policy_of_checkpoint(PolicyCheckpoint(net.state_dict(), bounds.low, bounds.high, info()),
                                          f"{out.name}@{trainer.iteration}")
        result = acceptance(policy, map_fn=backend.map, recovery=args.validate_recovery)
        row = evaluation_row(trainer.iteration, wall(), trainer.env_steps, result)
        append_csv(out / "eval.csv", row)
        scalars.evaluation(row)
        baseline = trainer.iteration == 0  # the warm start: logged, not a trained policy
        if baseline:
            warm_start_result["passed"] = result["passed"]
            warm_start_result["failures"] = result["failures"]
        elif result["passed"] and first_pass is None:
            first_pass = {k: row[k] for k in ("iteration", "wall_s", "env_steps")}
        if not baseline and (best is None or list(acceptance_rank(result)) < best["rank"]):
            best = {**row, "rank": list(acceptance_rank(result))}
            save_policy("best", {"acceptance": result})
        if args.keep_evaluated:
            (out / "evaluated").mkdir(exist_ok=True)
            save_policy(f"evaluated/{trainer.iteration:05d}", {"acceptance": result})
        bar.write(f"  acceptance @ {trainer.iteration}: {'PASSED' if result['passed'] else 'failed'} "
                  f"({row['failures']} failed checks, worst speed error {row['worst_speed_error']}, "
                  f"slowest reach {row['slowest_reach_s']} s)")

    def interrupt(_signum, _frame):
        raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)  # SIGTERM saves a checkpoint like Ctrl-C
    bar = tqdm(total=args.iterations, initial=trainer.iteration, unit="it", disable=args.no_progress,
               dynamic_ncols=True)
    if args.no_progress:
        bar.write = print  # type: ignore[method-assign]
    interrupted = False
    try:
        if args.eval_every and trainer.iteration == 0:
            evaluate()  # the starting point (warm start) as a baseline
        while trainer.iteration < args.iterations:
            stats = trainer.step()
            append_csv(out / "log.csv", {"wall_s": round(wall(), 1), **stats})
            scalars.iteration(stats, wall())
            bar.update(1)
            bar.set_postfix(ret=f"{stats['episode_return']:.3f}", err=f"{stats['mean_abs_error']:.3f}",
                            falls=f"{stats['fall_fraction']:.2f}")
            if args.no_progress:
                print(strict_json.dumps(stats), flush=True)
            if args.eval_every and trainer.iteration % args.eval_every == 0:
                evaluate()
                if args.stop_when_passed and first_pass is not None:
                    break
            if trainer.iteration % args.checkpoint_every == 0:
                save_checkpoint()
    except KeyboardInterrupt:
        interrupted = True
        bar.write("interrupted: saving a checkpoint")
    finally:
        bar.close()
        scalars.close()
        save_checkpoint()
        if not interrupted:
            trainer.close()
            backend.close()
    print(strict_json.dumps({"out": str(out), "iteration": trainer.iteration, "env_steps": trainer.env_steps,
                      "wall_s": round(wall(), 1), "first_pass": first_pass,
                      "best": None if best is None else {k: best[k] for k in ("iteration", "failures", "total_error")}}))
    if interrupted:
        stop_workers(trainer, backend)
    return 0


def stop_workers(trainer, backend) -> None:
    """After Ctrl-C/SIGTERM, with the checkpoint written: stop the pools (which also stops
    them from starting replacement workers), kill and reap whatever worker is left, and
    leave without multiprocessing's exit handlers. ``Pool.terminate()`` can block on a
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
    os._exit(0)


def append_csv(path: Path, row: dict) -> None:
    """Append ``row``; write the header first if the file is new."""
    new = not path.exists()
    with path.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(row))
        if new:
            writer.writeheader()
        writer.writerow(row)
