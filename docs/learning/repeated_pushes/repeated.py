# Repeated pushes (the paper's scenario shape: three equal pushes 2 s apart), broadly: first push
# at 2.0-2.5 s in 0.1 s steps (6 offsets) x 4 impulses per speed; survived = neither fell nor
# stalled within 10 s. For the memory variants of memory_probe.py (MODE, LEVEL as there):
#   .venv/bin/python docs/learning/repeated_pushes/repeated.py [base|skip] [LEVEL]
# repeated.txt: "base" and "skip" ran on the package of 08abeef (the memory kept every step);
# "classic" is the same trials for classic HZD. Since ec29e5a the package forgets at 0.9
# (RecoveryConfig.forget_weight), and "base" gives the "skip level 0.9" lines.
import sys
from concurrent.futures import ProcessPoolExecutor

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import memory_probe as mp  # noqa: E402  (patches the rule for MODE skip)

from rabbit_policy.evaluation.push_recovery import PushScenario, push_trial  # noqa: E402
from rabbit_policy.runtime.policies import make_policy  # noqa: E402

IMPULSES = {0.7: (-8, -10, -12, -14), 1.0: (-13, -16, -19, -22), 1.3: (-18, -22, -26, -30)}
OFFSETS = (2.0, 2.1, 2.2, 2.3, 2.4, 2.5)


def trial(job):
    kind, speed, impulse, t0 = job
    scenario = PushScenario("r", impulse / 0.1, times=(t0, t0 + 2.0, t0 + 4.0))
    return not push_trial(make_policy(kind), speed, scenario).failed


def main():
    label = f"{mp.MODE}{'' if mp.MODE == 'base' else ' level ' + str(mp.LEVEL)}"
    with ProcessPoolExecutor(2) as pool:
        for kind in ("recovery", "learned"):
            counts = []
            for speed, impulses in IMPULSES.items():
                ok = list(pool.map(trial, [(kind, speed, i, t) for i in impulses for t in OFFSETS]))
                counts.append([sum(ok[k * len(OFFSETS):(k + 1) * len(OFFSETS)]) for k in range(len(impulses))])
            print(label, kind, "survived of 6 per impulse:",
                  "; ".join(f"{s} m/s {dict(zip(IMPULSES[s], c))}" for s, c in zip(IMPULSES, counts)),
                  "total", sum(map(sum, counts)), flush=True)


if __name__ == "__main__":
    main()
