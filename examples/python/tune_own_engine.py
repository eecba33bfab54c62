"""Tune the model to an engine from Python: campaign -> the paper's tuning steps -> validation.

Without --data, a virtual engine plays yours: the published engine with a heavier turbo, larger
manifolds and a slower VGT actuator (mvem.lab writes its campaign, with realistic noise, as
`mvem lab` would), so the tuned values can be checked against the truth. With --data DIR, your
own campaign (docs/tuning-data.md) and --params FILE with your engine's constants.

    python examples/python/tune_own_engine.py                  # virtual engine, steps 1-4
    python examples/python/tune_own_engine.py --steps 1-5      # the full method (about a minute)
    python examples/python/tune_own_engine.py --data my_campaign --params my_engine.toml

Prints the tuned parameters (with the truth and the error in standard errors for the virtual
engine), the validation errors per data set (eq. (5), per cent) and writes tuned.toml.
"""

import argparse
import pathlib
import tempfile
import warnings

import mvem

# the virtual engine: what the published set differs in
VIRTUAL = {
    "turbo": {"j_t": 3.0e-4},
    "intake_manifold": {"v_im": 0.026},
    "exhaust_manifold": {"v_em": 0.024},
    "vgt_actuator": {"tau_vgt": 0.04},
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="campaign directory (default: a virtual engine's)")
    ap.add_argument("--params", help="your engine's constants (TOML/JSON parameter file)")
    ap.add_argument("--steps", default="1-4", help="tuning steps (default 1-4; 1-5: full)")
    ap.add_argument("--out", default="tuned.toml", help="tuned parameter file to write")
    ap.add_argument("--seed", type=int, default=3, help="virtual campaign's noise seed")
    a = ap.parse_args()

    with tempfile.TemporaryDirectory() as tmp:
        data, truth = a.data, None
        if data is None:
            data = pathlib.Path(tmp) / "campaign"
            c = mvem.lab(data, params=VIRTUAL, seed=a.seed)
            print(f"virtual campaign: {c['stationary']} stationary points, sets "
                  f"{','.join(c['datasets'])}, {c['samples']} samples")
            truth = mvem.published_params()
            for group, values in VIRTUAL.items():
                truth[group].update(values)

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            t = mvem.tune(data, params=a.params, steps=a.steps)
        for w in caught:
            print(f"warning: {w.message}")
        pathlib.Path(a.out).write_text(t["toml"])
        print(f"wrote {a.out} (steps {a.steps}, {t['report']['total_seconds']:.1f} s)")

        print(f"\n{'parameter':28s} {'tuned':>12s} {'std. error':>11s}"
              + (f" {'truth':>12s} {'z':>6s}" if truth else ""))
        worst = 0.0
        for name, e in sorted(t["report"]["parameters"].items()):
            if e.get("step") not in (2, 3) or "." not in name or "[" in name:
                continue
            se = e["std_error"]
            line = f"{name:28s} {e['value']:12.5g} " + (f"{se:11.3g}" if se else f"{'-':>11s}")
            group, key = name.split(".")
            if truth and group in truth and se:
                z = (e["value"] - truth[group][key]) / e["std_error"]
                line += f" {truth[group][key]:12.5g} {z:6.2f}"
                if e["identifiable"]:
                    worst = max(worst, abs(z))
            if not e["identifiable"]:
                line += f"  (not identifiable: {e['reason']})"
            print(line)
        if truth:
            print(f"largest |z| of the identifiable dynamic and actuator parameters: {worst:.2f}")

        # validation with the tuned file (its [test_cell]: tau_Me, sensor time constants)
        v = mvem.validate(data, params=a.out)
        print(f"\n{'set':4s} mean relative error per output [%] (eq. (5))")
        for s, outputs in v["datasets"].items():
            print(f"{s:4s} " + ", ".join(f"{o} {p:.2f}" for o, p in outputs.items()))
        print("stationary [%] (eq. (4)): "
              + ", ".join(f"{o} {p:.2f}" for o, p in v["stationary"].items()))


if __name__ == "__main__":
    main()
