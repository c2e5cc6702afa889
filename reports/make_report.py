#!/usr/bin/python3
"""Writes the reproduction report of `crease experiment run` results.

    /usr/bin/python3 reports/make_report.py RESULTS_DIR [-o OUT]

RESULTS_DIR is one experiment folder (it holds experiment.json) or a folder whose
subfolders are experiment folders. Writes OUT/report.md, OUT/claims.json and
OUT/figures/<experiment>_<figure>.png/.pdf (OUT defaults to RESULTS_DIR). The input
format, the claim grammar and the verdict rules are in reports/README.md.

Output is deterministic: no timestamps, sorted keys, fixed number formatting, and
figures saved without date or software metadata. Only numpy and matplotlib (Agg).
Exit code 0 when at least one experiment was reported, 1 when none could be, 2 on
bad arguments.
"""
import argparse
import json
import math
import os
import shutil
import sys

import numpy as np

VERDICTS = ("reproduced", "partly", "not reproduced", "not measured")
TREND_MIN_RHO = 0.5  # |Spearman rho| a trend claim needs to hold
# Metric-key suffix -> unit shown in claim measurements and figure axes.
UNITS = {"px": "px", "mm": "mm", "um": "µm", "ms": "ms", "s": "s", "deg": "deg",
         "pct": "%", "fps": "frames/s", "mb": "MB"}
DASH = "—"


def warn(msg):
    print(f"report: {msg}", file=sys.stderr)


# ----------------------------------------------------------------------------- numbers

def is_num(v):
    """A real number (bool is not a number here)."""
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def finite(v):
    return is_num(v) and math.isfinite(v)


def fmt_num(x, sig=3):
    """x to `sig` significant digits; returns (text, decimals used)."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return DASH, 0
    if math.isinf(x):
        return ("inf" if x > 0 else "-inf"), 0
    if x == 0:
        return "0", max(sig - 1, 0)
    e = math.floor(math.log10(abs(x)))
    if e < -3 or e >= 6:
        return f"{x:.{sig - 1}e}", sig - 1 - e
    dec = sig - 1 - e
    r = round(x, dec)
    if r != 0 and math.floor(math.log10(abs(r))) != e:  # rounding carried (9.996 -> 10.0)
        dec -= 1
        r = round(x, dec)
    if r == 0:
        r = 0.0  # no "-0.00"
    return f"{r:.{max(dec, 0)}f}", dec


def mean_std(values):
    """(mean, std with ddof=1 or None, n) of the finite values; mean None when empty."""
    v = [float(x) for x in values if finite(x)]
    if not v:
        return None, None, 0
    a = np.asarray(v)
    return float(a.mean()), (float(a.std(ddof=1)) if len(v) > 1 else None), len(v)


def fmt_mean_std(mean, std, unit=""):
    """'5.95 ± 0.21 px': mean to 3 significant digits, std to the mean's decimals."""
    if mean is None:
        return DASH
    m, dec = fmt_num(mean)
    text = m
    if std is not None and math.isfinite(std) and "e" not in m:
        s = round(std, max(dec, 0)) if dec >= 0 else round(std, dec)
        if s == 0 and std > 0:
            s_text = fmt_num(std, 1)[0]
        else:
            s_text = f"{s:.{max(dec, 0)}f}"
        text += f" ± {s_text}"
    elif std is not None and math.isfinite(std):
        text += f" ± {fmt_num(std)[0]}"
    return text + (f" {unit}" if unit else "")


def fmt_value(v):
    """A sweep-point value or claim operand as written by the user."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def value_key(v):
    """Sort key: numbers, then booleans, then strings."""
    if isinstance(v, bool):
        return (1, int(v), "")
    if is_num(v):
        return (0, float(v), "")
    return (2, 0.0, str(v))


def values_equal(a, b):
    if isinstance(a, bool) or isinstance(b, bool):
        return isinstance(a, bool) and isinstance(b, bool) and a == b
    if is_num(a) and is_num(b):
        return math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)
    return a == b


def spearman(x, y):
    """Spearman rank correlation with average ranks for ties; 0 when either is constant."""
    def ranks(a):
        a = np.asarray(a, dtype=float)
        order = np.argsort(a, kind="mergesort")
        r = np.empty(len(a))
        i = 0
        while i < len(a):
            j = i
            while j + 1 < len(a) and a[order[j + 1]] == a[order[i]]:
                j += 1
            r[order[i:j + 1]] = (i + j) / 2.0 + 1.0
            i = j + 1
        return r
    rx, ry = ranks(x), ranks(y)
    rx -= rx.mean()
    ry -= ry.mean()
    den = math.sqrt(float((rx * rx).sum() * (ry * ry).sum()))
    return float((rx * ry).sum() / den) if den > 0 else 0.0


def unit_of(key):
    last = key.rsplit(".", 1)[-1]
    if "_" in last:
        suffix = last.rsplit("_", 1)[1].lower()
        if suffix in UNITS:
            return UNITS[suffix]
    return ""


def label_of(key):
    """Short name of a metric: its last component without the unit suffix."""
    last = key.rsplit(".", 1)[-1]
    if unit_of(key):
        last = last.rsplit("_", 1)[0]
    return last.replace("_", " ")


def md_cell(text):
    return str(text).replace("|", "\\|").replace("\n", " ")


def plural(n, word):
    return f"{n} {word}" + ("" if n == 1 else "s")


# ----------------------------------------------------------------------------- loading

class Run:
    def __init__(self, data, path):
        self.path = path
        stem = os.path.splitext(os.path.basename(path))[0]
        self.run_id = str(data.get("run_id", stem))
        self.seed = data.get("seed")
        self.point = data.get("point") or {}
        self.status = data.get("status", "ok")
        self.error = data.get("error", "")
        self.metrics = data.get("metrics") or {}
        self.curves = data.get("curves") or {}
        self.images = data.get("images") or {}
        self.seconds = data.get("seconds")
        if not (self.seed is None or isinstance(self.seed, (int, str))):
            raise ValueError('"seed" is neither a number nor a string')
        if not isinstance(self.status, str):
            raise ValueError('"status" is not a string')
        for field, value in (("point", self.point), ("metrics", self.metrics),
                             ("curves", self.curves)):
            if not isinstance(value, dict):
                raise ValueError(f'"{field}" is not an object')

    @property
    def ok(self):
        return self.status == "ok"

    def metric(self, key):
        v = self.metrics.get(key)
        return float(v) if finite(v) else None


class Experiment:
    def __init__(self, folder, meta):
        self.folder = folder
        self.meta = meta
        self.name = str(meta.get("name") or os.path.basename(os.path.normpath(folder)))
        self.file_name = self.name  # made unique across experiments later
        self.runs = []
        self.notes = []  # problems found while reading, shown in the report
        sweep = meta.get("sweep") or {}
        self.sweep_mode = sweep.get("mode", "none")
        self.sweep_keys = [str(k) for k in (sweep.get("keys") or [])]
        for field in ("seeds", "table", "figures", "claims", "runs", "runs_failed"):
            if not isinstance(meta.get(field, []), list):
                raise ValueError(f'"{field}" is not a list')

    def ok_runs(self):
        return [r for r in self.runs if r.ok]

    def point_keys(self):
        keys = list(self.sweep_keys)
        for r in self.runs:
            for k in sorted(r.point):
                if k not in keys:
                    keys.append(k)
        return keys

    def point_sort_key(self, point):
        # Per key: present values first, sorted by value; then points without the key.
        return tuple((0,) + value_key(point[k]) if k in point else (1, 0, 0.0, "")
                     for k in self.point_keys())

    def points(self):
        """Distinct sweep points of the ok runs, sorted by their values."""
        seen = {}
        for r in self.ok_runs():
            seen.setdefault(json.dumps(r.point, sort_keys=True), r.point)
        return sorted(seen.values(), key=self.point_sort_key)

    def runs_at(self, point):
        key = json.dumps(point, sort_keys=True)
        return [r for r in self.ok_runs() if json.dumps(r.point, sort_keys=True) == key]


def read_json(path):
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def load_experiment(folder, label):
    """An Experiment, or (None, message) when experiment.json is missing or malformed."""
    meta_path = os.path.join(folder, "experiment.json")
    try:
        meta = read_json(meta_path)
        if not isinstance(meta, dict):
            raise ValueError("top level is not an object")
    except FileNotFoundError:
        return None, f"{label}/experiment.json: file not found; experiment skipped"
    except (OSError, ValueError) as e:
        return None, f"{label}/experiment.json: cannot read ({e}); experiment skipped"
    try:
        exp = Experiment(folder, meta)
    except (AttributeError, TypeError, ValueError) as e:
        return None, f"{label}/experiment.json: malformed ({e}); experiment skipped"
    runs_dir = os.path.join(folder, "runs")
    files = sorted(f for f in os.listdir(runs_dir) if f.endswith(".json")) \
        if os.path.isdir(runs_dir) else []
    if not files:
        exp.notes.append(f"`{label}/runs/` holds no run files.")
    listed = meta.get("runs")
    if isinstance(listed, list):
        # Run files of an earlier plan (another sweep or seed count) stay in runs/ when
        # the experiment is re-run; only the runs of the last plan are reported.
        planned = {str(rid) for rid in listed}
        stale = [f for f in files if os.path.splitext(f)[0] not in planned]
        for f in stale:
            exp.notes.append(f"Run file `{label}/runs/{f}` is not among experiment.json's runs (left from an "
                             "earlier plan of the experiment); it is left out.")
        files = [f for f in files if f not in stale]
    for f in files:
        path = os.path.join(runs_dir, f)
        try:
            data = read_json(path)
            if not isinstance(data, dict):
                raise ValueError("top level is not an object")
            exp.runs.append(Run(data, path))
        except (OSError, ValueError, AttributeError, TypeError) as e:
            msg = f"{label}/runs/{f}: cannot read ({e}); run skipped"
            warn(msg)
            exp.notes.append(f"Run file `{label}/runs/{f}` could not be read ({e}); "
                             "the run is left out of tables, figures and claims.")
    have = {os.path.splitext(os.path.basename(r.path))[0] for r in exp.runs} | \
        {r.run_id for r in exp.runs}
    unreadable = {os.path.splitext(f)[0] for f in files}
    for rid in meta.get("runs") or []:
        if str(rid) not in have and str(rid) not in unreadable:
            exp.notes.append(f"Run `{rid}` is listed in experiment.json but "
                             f"`runs/{rid}.json` is missing.")
    exp.runs.sort(key=lambda r: (exp.point_sort_key(r.point), value_key(r.seed), r.run_id))
    return exp, None


def find_experiments(results_dir):
    """Experiments (sorted by folder) and messages about folders that were skipped."""
    if os.path.isfile(os.path.join(results_dir, "experiment.json")):
        label = os.path.basename(os.path.normpath(results_dir))
        exp, msg = load_experiment(results_dir, label)
        return ([exp] if exp else []), ([msg] if msg else [])
    exps, skipped = [], []
    for sub in sorted(os.listdir(results_dir)):
        folder = os.path.join(results_dir, sub)
        if not os.path.isdir(folder) or sub == "figures":
            continue
        looks_like = any(os.path.exists(os.path.join(folder, f))
                         for f in ("experiment.json", "runs", "results.csv"))
        if not looks_like:
            continue
        exp, msg = load_experiment(folder, sub)
        if exp:
            exps.append(exp)
        else:
            skipped.append(msg)
    # Unique figure-file prefixes: the experiment name, else its folder name.
    used = set()
    for e in exps:
        name = e.name
        if name in used:
            name = os.path.basename(os.path.normpath(e.folder))
        base, i = name, 2
        while name in used:
            name, i = f"{base}_{i}", i + 1
        used.add(name)
        e.file_name = name
    return exps, skipped


# ----------------------------------------------------------------------------- claims

def where_matches(point, where):
    return all(k in point and values_equal(point[k], v) for k, v in where.items())


def fmt_where(where):
    return ", ".join(f"{k} = {fmt_value(v)}" for k, v in sorted(where.items()))


class Operand:
    """A claim operand: a metric key or a number."""

    def __init__(self, spec):
        if is_num(spec):
            self.key, self.const = None, float(spec)
        elif isinstance(spec, str):
            self.key, self.const = spec, None
        else:
            raise ValueError(f"operand {spec!r} is neither a metric key nor a number")

    def value(self, run):
        return self.const if self.key is None else run.metric(self.key)

    def describe(self, values, labels):
        if self.key is None:
            return fmt_value(self.const if not self.const.is_integer() else int(self.const))
        m, s, _ = mean_std(values)
        return f"{labels[self.key]} {fmt_mean_std(m, s, unit_of(self.key))}"


def seeds_text(held, total):
    return f"({held}/{total} seed{'s' if total != 1 else ''})"


def verdict_from(holds_mean, seed_results):
    if not holds_mean:
        return "not reproduced"
    return "reproduced" if all(seed_results) else "partly"


def evaluate_compare(op, args, runs):
    """less / greater / between on the mean over runs and per seed."""
    if op in ("less", "greater"):
        if not isinstance(args, list) or len(args) != 2:
            raise ValueError(f'"{op}" needs [A, B]')
    elif not isinstance(args, list) or len(args) != 3:
        raise ValueError('"between" needs [A, lo, hi]')
    ops = [Operand(a) for a in args]
    keys = [o.key for o in ops if o.key]
    if not keys:
        raise ValueError("no metric in the check")
    missing = [k for k in keys if all(r.metric(k) is None for r in runs)]
    if missing:
        return "not measured", "no value for " + ", ".join(f"`{k}`" for k in missing)
    # Pair the operands within each run: only runs where every metric has a value.
    paired = [r for r in runs if all(o.value(r) is not None for o in ops)]
    if not paired:
        return "not measured", "no run has all of " + ", ".join(f"`{k}`" for k in keys)

    def holds(rs):
        m = [float(np.mean([o.value(r) for r in rs])) for o in ops]
        if op == "less":
            return m[0] < m[1]
        if op == "greater":
            return m[0] > m[1]
        return m[1] <= m[0] <= m[2]

    seeds = sorted({r.seed for r in paired}, key=value_key)
    seed_ok = [holds([r for r in paired if r.seed == s]) for s in seeds]
    hold = holds(paired)
    short = {}
    for k in keys:
        short[k] = label_of(k)
    if len(set(short.values())) < len(short):
        short = {k: k for k in keys}
    vals = [[o.value(r) for r in paired] for o in ops]
    d = [o.describe(v, short) for o, v in zip(ops, vals)]
    if op == "between":
        text = f"{d[0]} in [{d[1]}, {d[2]}]"
    else:
        text = f"{d[0]} vs {d[1]}"
    text += f" {seeds_text(sum(seed_ok), len(seeds))}"
    if len(paired) < len(runs):
        text += f"; {len(paired)}/{len(runs)} runs have every value"
    return verdict_from(hold, seed_ok), text


def evaluate_trend(spec, runs):
    if not isinstance(spec, dict) or "x" not in spec or "y" not in spec:
        raise ValueError('"trend" needs {"x": KEY, "y": METRIC, "direction": ...}')
    x, y = str(spec["x"]), str(spec["y"])
    direction = spec.get("direction", "increasing")
    if direction not in ("increasing", "decreasing"):
        raise ValueError(f'unknown trend direction "{direction}"')
    sign = 1.0 if direction == "increasing" else -1.0
    rs = [r for r in runs if x in r.point]
    if not rs:
        return "not measured", f"no run varies `{x}`"
    if not all(is_num(r.point[x]) for r in rs):
        return "not measured", f"`{x}` is not numeric"
    rs = [r for r in rs if r.metric(y) is not None]
    if not rs:
        return "not measured", f"no value for `{y}`"

    def rho_of(sub):
        xs = sorted({float(r.point[x]) for r in sub})
        means = [float(np.mean([r.metric(y) for r in sub if float(r.point[x]) == v]))
                 for v in xs]
        return (spearman(xs, means) if len(xs) >= 2 else None), xs, means

    rho, xs, means = rho_of(rs)
    if rho is None:
        return "not measured", f"`{x}` takes one value only"
    seeds = sorted({r.seed for r in rs}, key=value_key)
    seed_rhos = [rho_of([r for r in rs if r.seed == s])[0] for s in seeds]
    seed_rhos = [p for p in seed_rhos if p is not None]
    seed_ok = [p * sign > 0 and abs(p) >= TREND_MIN_RHO for p in seed_rhos]
    if rho * sign > 0 and abs(rho) >= TREND_MIN_RHO:
        verdict = "reproduced" if all(seed_ok) else "partly"
    elif rho * sign > 0:
        verdict = "partly"
    else:
        verdict = "not reproduced"
    unit = unit_of(y)
    path = " → ".join(fmt_num(m)[0] for m in means) if len(means) <= 6 else \
        f"{fmt_num(means[0])[0]} → … → {fmt_num(means[-1])[0]}"
    text = (f"ρ = {rho:+.2f} over {len(xs)} values of {x} "
            f"({fmt_value(xs[0])} … {fmt_value(xs[-1])}); {label_of(y)}: {path}"
            f"{' ' + unit if unit else ''} {seeds_text(sum(seed_ok), len(seed_rhos))}")
    return verdict, text


def evaluate_claim(exp, claim):
    """(verdict, measurement text) of one claim."""
    where = claim.get("where") or {}
    if not isinstance(where, dict):
        return "not measured", '"where" is not an object'
    check = claim.get("check")
    if not isinstance(check, dict) or len(check) != 1:
        return "not measured", 'malformed "check" (needs exactly one of less, greater, ' \
            'between, trend)'
    runs = [r for r in exp.ok_runs() if where_matches(r.point, where)]
    if not runs:
        return "not measured", "no run matches" + (f" {fmt_where(where)}" if where else "")
    (op, args), = check.items()
    try:
        if op in ("less", "greater", "between"):
            return evaluate_compare(op, args, runs)
        if op == "trend":
            return evaluate_trend(args, runs)
        return "not measured", f'unknown check "{op}"'
    except ValueError as e:
        return "not measured", f"malformed check: {e}"


# ----------------------------------------------------------------------------- figures

_plt = None


def pyplot():
    global _plt
    if _plt is None:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        plt.rcParams.update({"font.size": 9, "axes.titlesize": 9, "legend.fontsize": 8,
                             "svg.hashsalt": "crease", "figure.dpi": 100})
        _plt = plt
    return _plt


def subplots(n):
    plt = pyplot()
    ncols = min(max(n, 1), 3)
    nrows = math.ceil(max(n, 1) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(8, 5), layout="constrained", squeeze=False)
    axes = axes.ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:max(n, 1)]


def figure_sweep(exp, spec):
    x = spec["x"]
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    runs = [r for r in exp.ok_runs() if x in r.point]
    if not runs:
        raise ValueError(f"no run varies `{x}`")
    xs = sorted({json.dumps(r.point[x]) for r in runs}, key=lambda v: value_key(json.loads(v)))
    xs = [json.loads(v) for v in xs]
    numeric = all(is_num(v) for v in xs)
    pos = [float(v) for v in xs] if numeric else list(range(len(xs)))
    fig, axes = subplots(len(ys))
    for ax, y in zip(axes, ys):
        means, stds = [], []
        for v in xs:
            m, s, _ = mean_std(r.metric(y) for r in runs if values_equal(r.point[x], v))
            means.append(np.nan if m is None else m)
            stds.append(0.0 if s is None else s)
        # Categorical x (strings, booleans): points only, no line between categories.
        ax.errorbar(pos, means, yerr=stds, marker="o", capsize=3, lw=1.2, ms=4,
                    ls="-" if numeric else "none")
        if not numeric:
            ax.set_xlim(-0.5, len(pos) - 0.5)
        if spec.get("logx") and numeric and all(p > 0 for p in pos):
            ax.set_xscale("log")
            ax.minorticks_off()
        ax.set_xticks(pos)
        ax.set_xticklabels([fmt_value(v) for v in xs])
        ax.set_xlabel(x)
        ax.set_ylabel(unit_of(y) or label_of(y))
        # A long metric name would run into its neighbour's title: break it at its last dot.
        ax.set_title(y if len(y) <= 30 else "\n".join(y.rsplit(".", 1)), fontsize=9)
        ax.grid(alpha=0.3)
    return fig, f"mean ± std over seeds of the runs that vary `{x}`"


def figure_curve(exp, spec):
    name = spec["curve"]
    curves = [r.curves[name] for r in exp.ok_runs() if isinstance(r.curves.get(name), list)]
    if not curves:
        raise ValueError(f'no run has curve "{name}"')
    n = max(len(c) for c in curves)
    a = np.full((len(curves), n), np.nan)
    for i, c in enumerate(curves):
        a[i, :len(c)] = [float(v) if finite(v) else np.nan for v in c]
    count = np.sum(np.isfinite(a), axis=0)
    with np.errstate(invalid="ignore"):
        mean = np.array([np.nanmean(col) if k else np.nan for col, k in zip(a.T, count)])
        std = np.array([np.nanstd(col, ddof=1) if k > 1 else 0.0 for col, k in zip(a.T, count)])
    t = np.arange(1, n + 1)
    fig, (ax,) = subplots(1)
    ax.plot(t, mean, marker="o" if n <= 30 else None, ms=3, lw=1.2,
            label=f"mean over {plural(len(curves), 'run')}")
    if len(curves) > 1:
        ax.fill_between(t, mean - std, mean + std, alpha=0.25, lw=0, label="± std")
    if is_num(spec.get("hline")):
        ax.axhline(spec["hline"], color="0.4", ls="--", lw=1,
                   label=fmt_value(spec["hline"]))
    ax.xaxis.set_major_locator(pyplot().MaxNLocator(integer=True))
    ax.set_xlabel(spec.get("x_label", "index"))
    ax.set_ylabel(spec.get("y_label", name))
    ax.set_title(spec.get("title", name))
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    return fig, f"curve `{name}`, mean ± std over {plural(len(curves), 'run')}"


def figure_per_frame(exp, spec):
    series = spec["series"] if isinstance(spec["series"], list) else [spec["series"]]
    cands = [r for r in exp.ok_runs() if any(isinstance(r.curves.get(s), list) for s in series)]
    if not cands:
        raise ValueError("no run has any of " + ", ".join(series))
    seed = min((r.seed for r in cands), key=value_key)
    run = next(r for r in cands if r.seed == seed)
    fig, (ax,) = subplots(1)
    for s in series:
        c = run.curves.get(s)
        if not isinstance(c, list):
            continue
        v = np.array([float(u) if finite(u) else np.nan for u in c])
        ax.plot(np.arange(len(v)), v, lw=1.0, label=s)
    ax.set_xlabel(spec.get("x_label", "frame"))
    ax.set_ylabel(spec.get("y_label", ""))
    ax.set_title(spec.get("title", f"per frame, run {run.run_id}"))
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    return fig, f"per frame, run `{run.run_id}` (gaps: untracked frames)"


def point_label(point):
    return ", ".join(f"{k}={fmt_value(v)}" for k, v in sorted(point.items())) or "all runs"


def bar_colours(n):
    """n distinct colours: tab10's up to 10; up to 20 tab20's dark shades, then its light
    ones (neighbours in tab20 are two shades of one hue); beyond, viridis evenly."""
    plt = pyplot()
    if n <= 10:
        return [plt.get_cmap("tab10")(i) for i in range(n)]
    if n <= 20:
        tab20 = plt.get_cmap("tab20")
        return [tab20(2 * i if i < 10 else 2 * (i - 10) + 1) for i in range(n)]
    return [plt.get_cmap("viridis")(i / (n - 1)) for i in range(n)]


def figure_bar(exp, spec):
    ys = spec["y"] if isinstance(spec["y"], list) else [spec["y"]]
    points = exp.points()
    if not points:
        raise ValueError("no successful run")
    fig, (ax,) = subplots(1)
    width = 0.8 / len(points)
    colours = bar_colours(len(points))
    for j, p in enumerate(points):
        rs = exp.runs_at(p)
        stats = [mean_std(r.metric(y) for r in rs) for y in ys]
        means = [np.nan if m is None else m for m, _, _ in stats]
        stds = [0.0 if s is None else s for _, s, _ in stats]
        pos = np.arange(len(ys)) + (j - (len(points) - 1) / 2.0) * width
        ax.bar(pos, means, width * 0.9, yerr=stds, capsize=3, color=colours[j],
               label=point_label(p) if len(points) > 1 else None)
    ax.set_xticks(np.arange(len(ys)))
    # Optional short tick labels ("labels": one per y); default: the metric keys.
    labels = spec.get("labels") if isinstance(spec.get("labels"), list) and len(spec["labels"]) == len(ys) else ys
    ax.set_xticklabels(labels, rotation=15 if len(ys) > 3 else 0)
    ax.set_ylabel(spec.get("y_label", ""))
    ax.set_title(spec.get("title", spec.get("name", "")))
    ax.grid(alpha=0.3, axis="y")
    if len(points) > 4:  # beside the axes (inside, a long legend covers the bars), on a wider figure
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        fig.set_size_inches(11, 5)
    elif len(points) > 1:
        ax.legend(loc="best")
    return fig, "mean ± std over seeds"


FIGURES = {"sweep": figure_sweep, "curve": figure_curve, "per_frame": figure_per_frame,
           "bar": figure_bar}


def copy_image(exp, spec, fig_dir, base):
    """Kind "image": a picture a run's stages made (e.g. eval's Fig. 11 error vectors),
    from the first run (lowest seed) that has it and matches the optional "where"."""
    name = spec["image"]
    where = spec.get("where") or {}
    cands = [r for r in exp.ok_runs() if isinstance(r.images.get(name), str)
             and all(r.point.get(k) == v for k, v in where.items())]
    if not cands:
        raise ValueError(f'no run has the image "{name}"')
    seed = min((r.seed for r in cands), key=value_key)
    run = next(r for r in cands if r.seed == seed)
    src = run.images[name]
    if not os.path.isfile(src):
        raise ValueError(f"{src}: missing")
    shutil.copyfile(src, os.path.join(fig_dir, base + ".png"))
    return f"run `{run.run_id}`"


def draw_figure(exp, spec, fig_dir):
    """Writes the PNG and PDF; returns (png file name, caption)."""
    kind = spec.get("kind")
    if kind == "image":
        base = "".join(c if c.isalnum() or c in "-_." else "_" for c in f"{exp.file_name}_{spec['name']}")
        return base, copy_image(exp, spec, fig_dir, base)
    if kind not in FIGURES:
        raise ValueError(f'unknown kind "{kind}"')
    fig, caption = FIGURES[kind](exp, spec)
    if spec.get("title") and kind in ("sweep",):
        fig.suptitle(spec["title"])
    base = f"{exp.file_name}_{spec['name']}"
    base = "".join(c if c.isalnum() or c in "-_." else "_" for c in base)
    fig.savefig(os.path.join(fig_dir, base + ".png"), dpi=100, metadata={"Software": None})
    fig.savefig(os.path.join(fig_dir, base + ".pdf"),
                metadata={"CreationDate": None, "Creator": None, "Producer": None})
    pyplot().close(fig)
    return base, caption


# ----------------------------------------------------------------------------- report

def metric_table(exp, lines):
    keys = exp.point_keys()
    table = [str(k) for k in (exp.meta.get("table") or [])]
    if not table:
        table = sorted({k for r in exp.ok_runs() for k in r.metrics})
    points = exp.points()
    if not points:
        lines.append("No successful run.\n")
        return
    head = [f"`{k}`" for k in keys] + ["runs"] + [f"`{m}`" for m in table]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "|".join(["---"] * len(keys) + ["--:"] * (1 + len(table))) + "|")
    for p in points:
        rs = exp.runs_at(p)
        cells = [fmt_value(p[k]) if k in p else "default" for k in keys]
        if not keys:
            cells = []
        cells.append(str(len(rs)))
        for m in table:
            mean, std, n = mean_std(r.metric(m) for r in rs)
            c = fmt_mean_std(mean, std)
            if 0 < n < len(rs):
                c += f" ({n}/{len(rs)})"
            cells.append(c)
        lines.append("| " + " | ".join(md_cell(c) for c in cells) + " |")
    lines.append("")
    lines.append("Cells: mean ± std over seeds (std with ddof = 1; one seed: the mean), "
                 "3 significant digits; (k/n): only k of the n runs have a value"
                 + ("; default: the key is not varied in that run" if exp.sweep_mode == "list"
                    or any(k not in p for p in points for k in keys) else "") + ".\n")


def describe_machine(machine):
    if isinstance(machine, dict):
        order = ["cpus", "cpu", "os"]
        ks = [k for k in order if k in machine] + sorted(k for k in machine if k not in order)
        return "; ".join(f"{k}: {machine[k]}" for k in ks)
    return str(machine) if machine else DASH


def experiment_section(exp, fig_dir, claims_out, fig_link="figures"):
    meta = exp.meta
    L = [f"## {meta.get('title') or exp.name}", ""]
    if meta.get("paper"):
        L += [f"**Paper:** {meta['paper']}", ""]
    if meta.get("description"):
        L += [str(meta["description"]).strip(), ""]
    seeds = meta.get("seeds")
    ok, failed = exp.ok_runs(), [r for r in exp.runs if not r.ok]
    L += [f"- experiment: `{exp.name}`; profile: {meta.get('profile', DASH)}; seeds: "
          + (", ".join(fmt_value(s) for s in seeds) if isinstance(seeds, list) else DASH),
          f"- sweep: {exp.sweep_mode}"
          + (" over " + ", ".join(f"`{k}`" for k in exp.sweep_keys) if exp.sweep_keys else ""),
          f"- crease: {meta.get('crease_version', DASH)}",
          f"- machine: {describe_machine(meta.get('machine'))}",
          f"- runs: {len(ok)} ok, {len(failed)} failed"
          + ("" if meta.get("complete", True) else "; **the experiment did not complete**"),
          ""]
    if meta.get("command"):
        L += ["```sh", str(meta["command"]), "```", ""]
    if exp.notes:
        L += ["**Problems reading the results:**", ""] + [f"- {n}" for n in exp.notes] + [""]

    L += ["### Results", ""]
    metric_table(exp, L)

    listed_failed = [str(x) for x in meta.get("runs_failed") or []]
    have_ids = {r.run_id for r in exp.runs}
    if failed or any(x not in have_ids for x in listed_failed):
        L += ["### Failed runs", ""]
        for r in failed:
            err = str(r.error or "no error message").strip().splitlines()
            L.append(f"- `{r.run_id}` (seed {fmt_value(r.seed)}): {err[0] if err else ''}")
        for x in listed_failed:
            if x not in have_ids:
                L.append(f"- `{x}`: listed as failed in experiment.json, no run file")
        L.append("")

    figures = meta.get("figures") or []
    if figures:
        L += ["### Figures", ""]
        for spec in figures:
            if not isinstance(spec, dict) or "name" not in spec:
                msg = f"figure {json.dumps(spec, sort_keys=True)} of `{exp.name}`: " \
                    "malformed (needs a name)"
                warn(msg)
                L += [f"- {msg}", ""]
                continue
            try:
                base, caption = draw_figure(exp, spec, fig_dir)
            except (KeyError, ValueError, TypeError) as e:
                msg = f"figure `{spec['name']}` of `{exp.name}` not drawn: {e}"
                warn(msg)
                L += [f"- {msg}", ""]
                continue
            title = spec.get("title") or spec["name"]
            pdf = "" if spec.get("kind") == "image" else f" ([pdf]({fig_link}/{base}.pdf))"
            L += [f"![{md_cell(title)}]({fig_link}/{base}.png)", "",
                  f"*{md_cell(title)}* — {caption}{pdf}.", ""]

    claims = meta.get("claims") or []
    if claims:
        L += ["### Claims", "", "| claim (paper) | crease measurement | verdict |",
              "|---|---|---|"]
        for i, c in enumerate(claims):
            if not isinstance(c, dict):
                c = {"id": f"claim-{i + 1}", "paper": str(c), "check": None}
            cid = str(c.get("id", f"claim-{i + 1}"))
            verdict, text = evaluate_claim(exp, c)
            paper = str(c.get("paper", ""))
            where = c.get("where") if isinstance(c.get("where"), dict) else {}
            cell = f"**{cid}**" + (f": {paper}" if paper else "") + \
                (f" (where {fmt_where(where)})" if where else "")
            L.append(f"| {md_cell(cell)} | {md_cell(text)} | {verdict} |")
            claims_out.append({"experiment": exp.name, "id": cid, "paper": paper,
                               "verdict": verdict, "measurement": text})
        L += ["", "Verdicts: see `reports/README.md` (the check on the mean over the selected "
              "runs, and per seed).", ""]
    return L


def make_report(results_dir, out_dir, markdown=None, preface=None):
    """`markdown`: where the report's Markdown goes (default OUT/report.md); its figure
    links are relative to it. `preface`: a Markdown file put after the introduction
    (how the results were made, caveats), so it survives regeneration."""
    preface_text = ""
    if preface:
        try:
            with open(preface, encoding="utf-8") as f:
                preface_text = f.read().strip()
        except OSError as e:
            warn(f"{preface}: cannot read the preface ({e.strerror})")
            return 2
    markdown = markdown or os.path.join(out_dir, "report.md")
    exps, skipped = find_experiments(results_dir)
    for msg in skipped:
        warn(msg)
    if not exps:
        warn(f"nothing to report in {results_dir}")
        return 1
    fig_dir = os.path.join(out_dir, "figures")
    os.makedirs(fig_dir, exist_ok=True)
    md_dir = os.path.dirname(os.path.abspath(markdown))
    os.makedirs(md_dir, exist_ok=True)
    fig_link = os.path.relpath(os.path.abspath(fig_dir), md_dir).replace(os.sep, "/")

    claims, sections, reported = [], [], []
    for e in exps:
        n_claims = len(claims)
        try:
            sections += experiment_section(e, fig_dir, claims, fig_link)
            reported.append(e)
        except Exception as err:  # a bug or an input this script did not foresee
            del claims[n_claims:]
            label = os.path.basename(os.path.normpath(e.folder))
            msg = f"{label}/experiment.json: could not be reported ({type(err).__name__}: {err}); " \
                "experiment skipped"
            warn(msg)
            skipped.append(msg)
    exps = reported
    if not exps:
        warn(f"nothing to report in {results_dir}")
        return 1

    H = ["# crease reproduction report", "",
         "Reproduction of Cao, Bradley, Zhou and Beeler, *Real-Time High-Fidelity Facial "
         "Performance Capture* (SIGGRAPH 2015), from the results of `crease experiment run` "
         f"in `{os.path.basename(os.path.normpath(os.path.abspath(results_dir)))}/` "
         "(written by `reports/make_report.py`).", "",
         "Experiments: " + ", ".join(f"`{e.name}`" for e in exps) + ".", ""]
    if preface_text:
        H += [preface_text, ""]
    if skipped:
        H += ["**Skipped:**", ""] + [f"- {m}" for m in skipped] + [""]
    H += ["## Summary of claims", ""]
    if claims:
        counts = {v: sum(c["verdict"] == v for c in claims) for v in VERDICTS}
        H += [", ".join(f"{counts[v]} {v}" for v in VERDICTS) + f" (of {len(claims)}).", "",
              "| experiment | claim | verdict | crease measurement |", "|---|---|---|---|"]
        H += [f"| {md_cell(c['experiment'])} | {md_cell(c['id'])} | {c['verdict']} | "
              f"{md_cell(c['measurement'])} |" for c in claims]
    else:
        H += ["No claims."]
    H.append("")

    with open(markdown, "w", encoding="utf-8") as f:
        f.write("\n".join(H + sections).rstrip("\n") + "\n")
    with open(os.path.join(out_dir, "claims.json"), "w", encoding="utf-8") as f:
        json.dump(claims, f, indent=1, sort_keys=True, ensure_ascii=False)
        f.write("\n")
    print(f"report: wrote {markdown} "
          f"({plural(len(exps), 'experiment')}, {plural(len(claims), 'claim')})")
    return 0


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("results_dir", metavar="RESULTS_DIR",
                    help="an experiment folder or a folder of experiment folders")
    ap.add_argument("-o", "--out", metavar="OUT",
                    help="where report.md, claims.json and figures/ go (default RESULTS_DIR)")
    ap.add_argument("--markdown", metavar="FILE",
                    help="write the report's Markdown here instead of OUT/report.md "
                    "(its figure links are relative to FILE)")
    ap.add_argument("--preface", metavar="FILE",
                    help="Markdown put after the report's introduction (how it was made, caveats)")
    a = ap.parse_args(argv)
    if not os.path.isdir(a.results_dir):
        warn(f"{a.results_dir}: not a folder")
        return 2
    out = a.out or a.results_dir
    os.makedirs(out, exist_ok=True)
    return make_report(a.results_dir, out, a.markdown, a.preface)


if __name__ == "__main__":
    sys.exit(main())
