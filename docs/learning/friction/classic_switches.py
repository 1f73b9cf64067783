# Classic HZD's ordered speed changes (check 2's 72: every ordered pair of 0.7-1.5 m/s at four
# phases) and 20 random one-minute command sequences (check 3's first 20 seeds) on a gait library.
#   .venv/bin/python docs/learning/friction/classic_switches.py [GAIT_DIR] > OUT
# classic_switches_shipped.txt (the shipped library, a copy of it), _030_family.txt (library_030
# with its calibration), _030_bridge.txt (library_030_bridge over library_030's 1.2-1.25 m/s).
from concurrent.futures import ProcessPoolExecutor
import sys
from dataclasses import replace

from rabbit_policy.evaluation.robustness import RobustnessConfig, random_sequences, transitions
from rabbit_policy.runtime.policies import make_policy

if __name__ == "__main__":
    directory = sys.argv[1] if len(sys.argv) > 1 else None
    policy = make_policy("classic", directory)
    config = RobustnessConfig()
    with ProcessPoolExecutor(2) as pool:
        t = transitions(policy, config, pool.map)
        bad = [f"{r['from']}->{r['to']}@{r['phase']}:{r['outcome']}" for r in t["rows"] if r["outcome"] != "walked"]
        print(f"ordered changes: {t['passed']} of {t['total']} within the reach time, {t['fell_or_stalled']} fell or "
              f"stalled: {' '.join(bad)}", flush=True)
        r = random_sequences(policy, replace(config, random_episodes=20), pool.map)
        print("random sequences (20):", {k: v for k, v in r.items() if k != "rows"}, flush=True)
