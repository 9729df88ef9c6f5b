"""Two versions of the discrepancy results files side by side: the same verdicts, the same values?

Compares the results files of :mod:`ha_trajectory_discrepancy` and :mod:`bench_discrepancy_sweep`
as committed at a git revision (``--base``, default the previous commit that changed them) with
the files in the working tree, and prints one Markdown table per file:

- Ha's trajectory: the verdict and the named effects; every candidate's fitted values with the
  difference in units of the earlier standard error; its out-of-fold mean; the test split's means
  (robot file, calibrated baseline, final model) with their relative differences; the run's
  wall time;
- the sweep: per case (seed) both outcomes and verdicts, the named effects' fitted values with
  their relative differences, the test split's mean of the final model, and the case's seconds.

A difference passes when the verdicts and named effects agree, every value lies within one
earlier standard error (Ha's candidates) or 2 % (sweep values without a standard error), and
every error figure within 2 %; the table marks the others. Exit status 0 either way: the table
is for a reader, who decides whether a difference is an improvement (e.g. a fit that now
converges).

    python benchmarks/compare_discrepancy_results.py [--base REV] [--ha FILE] [--sweep FILE]
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HA = "benchmarks/results/ha-trajectory-discrepancy.json"
SWEEP = "benchmarks/results/discrepancy-sweep.json"
#: Relative tolerance of an error figure, and of a value without a standard error.
RELATIVE = 0.02


def _at(rev: str, path: str) -> dict | None:
    res = subprocess.run(["git", "-C", str(ROOT), "show", f"{rev}:{path}"], capture_output=True, text=True)
    return json.loads(res.stdout) if res.returncode == 0 else None


def _last_change(path: str) -> str:
    """The revision before the last commit that changed ``path``."""
    out = subprocess.run(["git", "-C", str(ROOT), "log", "-n", "1", "--format=%H", "--", path],
                         capture_output=True, text=True, check=True).stdout.strip()
    return f"{out}~1" if out else "HEAD"


def _rel(a, b) -> float:
    if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)):
        return math.nan
    return abs(b - a) / max(abs(a), 1e-12)


def _fmt(v, digits=4) -> str:
    return "-" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.{digits}g}"


def _flag(ok: bool) -> str:
    return "" if ok else " **!**"


def compare_ha(old: dict, new: dict) -> list[str]:
    """Markdown lines comparing two results files of Ha's trajectory."""
    same = old["verdict"] == new["verdict"] and old["named_effects"] == new["named_effects"]
    lines = [f"Verdict: {old['verdict']} {old['named_effects']} | {new['verdict']} {new['named_effects']}{_flag(same)}",
             "", "| candidate | parameter | earlier (se) | now (se) | difference / earlier se | out-of-fold mean [mm] |",
             "|---|---|---|---|---|---|"]
    for name, c in old["candidates"].items():
        n = new["candidates"].get(name)
        if n is None:
            lines.append(f"| {name} | (not fitted now) | | | | |")
            continue
        oof = f"{_fmt(c['out_of_fold_mean_mm'])} / {_fmt(n['out_of_fold_mean_mm'])}" + _flag(
            _rel(c["out_of_fold_mean_mm"], n["out_of_fold_mean_mm"]) <= RELATIVE)
        params = c.get("parameters") or {"(none)": None}
        for i, (p, v) in enumerate(params.items()):
            if v is None:
                lines.append(f"| {name} | - | | | | {oof} |")
                continue
            w = (n.get("parameters") or {}).get(p, {})
            se = v.get("stderr")
            d = (w.get("value", math.nan) - v["value"]) / se if se and math.isfinite(se) and se > 0 else math.nan
            ok = (abs(d) <= 1.0) if math.isfinite(d) else _rel(v["value"], w.get("value")) <= RELATIVE
            lines.append(f"| {name if i == 0 else ''} | {p} | {_fmt(v['value'])} ({_fmt(se, 2)}) | "
                         f"{_fmt(w.get('value'))} ({_fmt(w.get('stderr'), 2)}) | {_fmt(d, 2)}{_flag(ok)} | "
                         f"{oof if i == 0 else ''} |")
    lines += ["", "| test split, mean [mm] | earlier | now | relative difference |", "|---|---|---|---|"]
    for k in ("file", "before", "after"):
        a, b = old["test_split"][k]["mean_mm"]["value"], new["test_split"][k]["mean_mm"]["value"]
        lines.append(f"| {k} | {_fmt(a)} | {_fmt(b)} | {_fmt(100 * _rel(a, b), 2)} %{_flag(_rel(a, b) <= RELATIVE)} |")
    lines.append("")
    lines.append(f"Wall time: {_fmt(old.get('seconds_this_invocation'))} s | {_fmt(new.get('seconds_this_invocation'))} s")
    return lines


def compare_sweep(old: dict, new: dict) -> list[str]:
    """Markdown lines comparing the cases two sweep results files have in common."""
    olds = {c["seed"]: c for c in old["cases"]}
    news = {c["seed"]: c for c in new["cases"]}
    lines = ["| seed | robot | truth | outcome earlier / now | named earlier / now | values earlier / now (rel.) | "
             "test mean after [mm] earlier / now | seconds earlier / now |", "|---|---|---|---|---|---|---|---|"]
    for seed in sorted(set(olds) & set(news)):
        a, b = olds[seed], news[seed]
        same = a["outcome"] == b["outcome"] and a["named_effects"] == b["named_effects"] and \
            a.get("ambiguous_with") == b.get("ambiguous_with")
        vals = []
        for e, params in (a.get("fitted") or {}).items():
            for p, v in params.items():
                w = (b.get("fitted") or {}).get(e, {}).get(p)
                r = _rel(v, w)
                vals.append(f"{p} {_fmt(v)} / {_fmt(w)} ({_fmt(100 * r, 2)} %){_flag(r <= RELATIVE)}")
        ta, tb = a["test_mean_mm"]["after"], b["test_mean_mm"]["after"]
        lines.append(f"| {seed} | {a['robot']} | {','.join(a['truth']) or 'none'} | {a['outcome']} / {b['outcome']}"
                     f"{_flag(same)} | {','.join(a['named_effects']) or '-'} / {','.join(b['named_effects']) or '-'} | "
                     f"{'; '.join(vals) or '-'} | {_fmt(ta)} / {_fmt(tb)}{_flag(_rel(ta, tb) <= RELATIVE)} | "
                     f"{a['seconds']:.0f} / {b['seconds']:.0f} |")
    only = sorted(set(olds) ^ set(news))
    if only:
        lines += ["", f"Cases in one file only: {only}"]
    sa = sorted(olds[s]["seconds"] for s in set(olds) & set(news))
    sb = sorted(news[s]["seconds"] for s in set(olds) & set(news))
    if sa:
        lines += ["", f"Case seconds, median: {sa[len(sa) // 2]:.0f} | {sb[len(sb) // 2]:.0f}; total "
                      f"{sum(sa):.0f} | {sum(sb):.0f}"]
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--base", default=None, help="git revision of the earlier files (default: before the last "
                                                 "commit that changed each file)")
    ap.add_argument("--ha", default=str(ROOT / HA), help="Ha trajectory results file to compare")
    ap.add_argument("--sweep", default=str(ROOT / SWEEP), help="sweep results file to compare")
    args = ap.parse_args(argv)
    for title, rel, path, fn in (("Ha's measured trajectory", HA, args.ha, compare_ha),
                                 ("Hidden effects over seeds", SWEEP, args.sweep, compare_sweep)):
        base = args.base or _last_change(rel)
        old = _at(base, rel)
        if old is None or not Path(path).exists():
            print(f"## {title}: nothing to compare ({rel} at {base} or {path} missing)\n")
            continue
        new = json.loads(Path(path).read_text())
        print(f"## {title}: {rel} at {base} | {path}\n")
        print("\n".join(fn(old, new)) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
