"""Probe (docs/learning.md, 2026-12-07): specs on the 940 paired screen trials (ScreenTrials()),
each after the first paired against it (McNemar, in all and per family). Usage:
    screen_pair.py OUT.json SPEC [SPEC ...]"""
import json, sys
from pathlib import Path
from rabbit_policy.evaluation.shipping import ScreenTrials, measure, pooled, FAMILIES
from rabbit_policy.evaluation.statistics import mcnemar_exact
from rabbit_policy.parallel import BackendConfig, make_backend
from rabbit_policy.spec import load_controller

out, specs = Path(sys.argv[1]), sys.argv[2:]
rows = []
backend = make_backend(BackendConfig(workers=2))
try:
    for spec in specs:
        row = {"spec": spec, **measure(load_controller(spec), ScreenTrials(), backend.map)}
        if rows:
            row["against_first"] = {"all": mcnemar_exact(pooled(row), pooled(rows[0])),
                                    **{f: mcnemar_exact(row["outcomes"][f], rows[0]["outcomes"][f]) for f in FAMILIES}}
        rows.append(row)
        print(spec, row["passed"], row["of"], {f: (r["k"], r["n"]) for f, r in row["rates"].items()},
              row.get("against_first", {}), flush=True)
        out.write_text(json.dumps(rows))
finally:
    backend.close()
