# Can a design-time "departure" term (walk the candidate, then switch straight to a slower
# library gait, as the approach term switches into the candidate) tell the friction-limited
# fast gaits from the shipped ones? 3 s on the fast gait, then the slower gait from the next
# touchdown (blend 0: at once; 0.2: over 0.2 of phase), one walk per row, 8 s after the switch.
#   .venv/bin/python docs/learning/friction/departure_probe.py > docs/learning/friction/departure_probe.txt
from rabbit_hzd_controller.controller import ControllerConfig
from rabbit_hzd_controller.gait import Gait
from rabbit_policy.experiment.loop import walk
from rabbit_policy.experiment.scenario import Scenario
from rabbit_policy.runtime.gait_library import GaitLibrary
from rabbit_policy.runtime.policies import LibraryPolicy

LIBRARY = GaitLibrary.load()
SOURCES = (("shipped", None), ("library_030", "docs/learning/friction/library_030"),
           ("library_030_bridge", "docs/learning/friction/library_030_bridge"))

for name, directory in SOURCES:
    for speed in (1.4, 1.5):
        fast = LIBRARY.nearest(speed) if directory is None else Gait.load(f"{directory}/gait_{speed:.2f}.json")
        cells = []
        for target in (0.8, 1.0, 1.2):
            slow = LIBRARY.nearest(target)
            for blend in (0.0, 0.2):
                policy = LibraryPolicy(GaitLibrary.from_gaits([fast, slow]), "nearest")
                r = walk(policy, Scenario(schedule=((0.0, speed), (3.0, target))), 11.0,
                         controller=ControllerConfig(blend_phase=blend))
                cells.append(f"{target}/{blend}: " + ("fell" if r.fell else "stalled" if r.stalled else
                                                      f"{r.mean_speed(7.0) - target:+.3f}"))
        print(f"{name} {speed}: " + " | ".join(cells), flush=True)
