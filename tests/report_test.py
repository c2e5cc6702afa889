#!/usr/bin/python3
"""Tests reports/make_report.py on the hand-written fixture tests/data/report_fixture/.

    /usr/bin/python3 tests/report_test.py        (exit code 0 = pass)

The fixture's numbers are chosen so that the expected table cells and claim measurements
can be worked out by hand; the comments give the arithmetic. Each case runs the script on
a copy of the fixture in a temporary folder, never on the fixture itself.
"""
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
SCRIPT = os.path.join(HERE, "..", "reports", "make_report.py")
FIXTURE = os.path.join(HERE, "data", "report_fixture")
FIGURES = ["ferns_ferns_K", "ferns_stages", "detail_pca_pca_energy",
           "detail_pca_tracking_per_frame"]

sys.dont_write_bytecode = True  # no __pycache__ in reports/
sys.path.insert(0, os.path.dirname(SCRIPT))
import make_report  # noqa: E402  (for the formatting and statistics helpers)


def run_report(*args):
    p = subprocess.run([sys.executable, SCRIPT, *args], capture_output=True, text=True,
                       timeout=120)
    return p.returncode, p.stdout, p.stderr


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def png_size(path):
    with open(path, "rb") as f:
        head = f.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", head[16:24])


class Helpers(unittest.TestCase):
    def test_three_significant_digits(self):
        f = lambda x: make_report.fmt_num(x)[0]
        self.assertEqual(f(5.95), "5.95")
        self.assertEqual(f(0.2), "0.200")
        self.assertEqual(f(1280), "1280")
        self.assertEqual(f(12345), "12300")
        self.assertEqual(f(9.996), "10.0")  # rounding carries into the next decade
        self.assertEqual(f(-0.0004), "-4.00e-04")
        self.assertEqual(f(0), "0")

    def test_mean_std(self):
        m, s, n = make_report.mean_std([5.8, 6.1, None, float("nan")])  # NaN/null skipped
        self.assertEqual(n, 2)
        self.assertEqual(make_report.fmt_mean_std(m, s, "px"), "5.95 ± 0.21 px")
        m, s, n = make_report.mean_std([3.0])
        self.assertEqual((make_report.fmt_mean_std(m, s), n), ("3.00", 1))  # one seed: no std
        self.assertEqual(make_report.fmt_mean_std(2.0, 0.002), "2.00 ± 0.002")

    def test_spearman(self):
        self.assertAlmostEqual(make_report.spearman([1, 2, 3], [10, 20, 30]), 1.0)
        self.assertAlmostEqual(make_report.spearman([1, 2, 3], [3, 2, 1]), -1.0)
        self.assertAlmostEqual(make_report.spearman([1, 2, 3, 4], [1, 1, 2, 2]), 0.894427191)
        self.assertEqual(make_report.spearman([1, 2, 3], [5, 5, 5]), 0.0)  # no trend


class Report(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.mkdtemp(prefix="crease_report_test_")
        self.results = os.path.join(self.tmp, "results")
        shutil.copytree(FIXTURE, self.results)

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def test_fixture_report(self):
        code, out, err = run_report(self.results)  # OUT defaults to RESULTS_DIR
        self.assertEqual(code, 0, err)
        self.assertEqual(err, "")
        md = read(os.path.join(self.results, "report.md"))

        # Summary at the top, one row per claim.
        summary = md.index("## Summary of claims")
        self.assertLess(summary, md.index("## Fern cascade ablation"))
        self.assertIn("4 reproduced, 1 partly, 1 not reproduced, 1 not measured (of 7).", md)
        # K = 1280: refined (5.8, 6.1) -> 5.95 ± 0.3/sqrt(2) = 0.21; coarse (6.40, 6.84)
        # -> 6.62 ± 0.44/sqrt(2) = 0.31; both seeds have refined < coarse.
        self.assertIn("| ferns | refinement-2d | reproduced | refined 5.95 ± 0.21 px vs "
                      "coarse 6.62 ± 0.31 px (2/2 seeds) |", md)
        # Means 0.43, 0.54, 0.64 rise with K, and per seed too: rho = +1.
        self.assertIn("| ferns | more-ferns-better-wrinkles | reproduced | ρ = +1.00 over 3 "
                      "values of training.num_ferns (80 … 1280); correlation: 0.430 → 0.540 "
                      "→ 0.640 (2/2 seeds) |", md)
        # Jitter at K = 1280: (0.040, 0.056) -> mean 0.048 < 0.05, but seed 2 has 0.056.
        self.assertIn("| ferns | jitter-small | partly | jitter band 0.0480 ± 0.0113 mm vs "
                      "0.05 (1/2 seeds) |", md)
        self.assertIn("| ferns | real-time | not measured | no value for `speed.frame_ms` |", md)
        self.assertIn("| ferns | wrinkles-faithful | not reproduced | correlation 0.640 ± "
                      "0.028 in [0.9, 1] (0/2 seeds) |", md)
        # detail_pca: the failed seed 3 is left out; refined (2.4, 2.6), coarse (3.1, 3.3).
        self.assertIn("| detail_pca | refinement-2d | reproduced | refined 2.50 ± 0.14 px vs "
                      "coarse 3.20 ± 0.14 px (2/2 seeds) |", md)
        self.assertIn("| detail_pca | pca-16-dims | reproduced | energy at 16 0.880 ± 0.028 "
                      "in [0.85, 1] (2/2 seeds) |", md)

        # Experiment header: reference, command, version, machine, seeds.
        self.assertIn("**Paper:** Sec. 4.3 (K = 1280 ferns, F = 5, beta = 1000)", md)
        self.assertIn("```sh\ncrease experiment run ferns --profile quick --seeds 2\n```", md)
        self.assertIn("- crease: 0.1.0 (git 38cc75b)", md)
        self.assertIn("- machine: cpus: 2; cpu: AMD EPYC 7B13; os: Linux 6.1 (Debian 12)", md)
        self.assertIn("- experiment: `ferns`; profile: quick; seeds: 1, 2", md)

        # Sweep table: rows sorted by K numerically (80 < 320 < 1280, not as strings);
        # the null flow time of K = 80 seed 2 is skipped and flagged (1/2).
        rows = ["| 80 | 2 | 7.20 ± 0.14 | 6.50 ± 0.14 | 0.430 ± 0.028 | 0.0920 ± 0.0028 | "
                "4.00 (1/2) |",
                "| 320 | 2 | 6.80 ± 0.14 | 6.20 ± 0.14 | 0.540 ± 0.014 | 0.0710 ± 0.0014 | "
                "4.30 ± 0.14 |",
                "| 1280 | 2 | 6.62 ± 0.31 | 5.95 ± 0.21 | 0.640 ± 0.028 | 0.0480 ± 0.0113 | "
                "4.70 ± 0.14 |"]
        pos = [md.index(r) for r in rows]
        self.assertEqual(pos, sorted(pos))
        self.assertIn("| 2 | 3.20 ± 0.14 | 2.50 ± 0.14 | 0.880 ± 0.028 |", md)

        # Failed run listed with its error; claims tables per experiment.
        self.assertIn("- `seed3` (seed 3): crease train: cannot open scans/actor3.ply", md)
        self.assertIn("- runs: 2 ok, 1 failed", md)
        self.assertEqual(md.count("| claim (paper) | crease measurement | verdict |"), 2)
        self.assertIn("| **jitter-small**: Regressed details are temporally stable (Sec. 6) "
                      "(where training.num_ferns = 1280) | jitter band 0.0480 ± 0.0113 mm vs "
                      "0.05 (1/2 seeds) | partly |", md)

        # Figures: embedded, PNG about 800 x 500, PDF present.
        for name in FIGURES:
            self.assertIn(f"](figures/{name}.png)", md)
            png = os.path.join(self.results, "figures", name + ".png")
            pdf = os.path.join(self.results, "figures", name + ".pdf")
            self.assertEqual(png_size(png), (800, 500), name)
            with open(pdf, "rb") as f:
                self.assertEqual(f.read(5), b"%PDF-")
            self.assertGreater(os.path.getsize(pdf), 1000)

        claims = json.loads(read(os.path.join(self.results, "claims.json")))
        self.assertEqual([(c["experiment"], c["id"], c["verdict"]) for c in claims], [
            ("detail_pca", "refinement-2d", "reproduced"),
            ("detail_pca", "pca-16-dims", "reproduced"),
            ("ferns", "refinement-2d", "reproduced"),
            ("ferns", "more-ferns-better-wrinkles", "reproduced"),
            ("ferns", "jitter-small", "partly"),
            ("ferns", "real-time", "not measured"),
            ("ferns", "wrinkles-faithful", "not reproduced")])
        self.assertTrue(all(c["measurement"] for c in claims))

        # Deterministic: a second run into another folder gives the same bytes.
        out2 = os.path.join(self.tmp, "out2")
        code, _, err = run_report(self.results, "-o", out2)
        self.assertEqual(code, 0, err)
        for rel in ["report.md", "claims.json"] + [f"figures/{n}.{e}" for n in FIGURES
                                                   for e in ("png", "pdf")]:
            with open(os.path.join(self.results, rel), "rb") as a, \
                    open(os.path.join(out2, rel), "rb") as b:
                self.assertEqual(a.read(), b.read(), rel)

    def test_markdown_elsewhere_links_the_figures_relative_to_it(self):
        # reports/REPRODUCTION.md with its figures in reports/paper/figures/.
        top = os.path.join(self.tmp, "reports")
        out = os.path.join(top, "paper")
        md_path = os.path.join(top, "REPRODUCTION.md")
        preface = os.path.join(self.tmp, "preface.md")
        with open(preface, "w", encoding="utf-8") as f:
            f.write("## How this was made\n\nOn two cores.\n")
        code, _, err = run_report(self.results, "-o", out, "--markdown", md_path, "--preface", preface)
        self.assertEqual(code, 0, err)
        md = read(md_path)
        # The preface sits between the introduction and the summary.
        self.assertLess(md.index("Experiments: "), md.index("## How this was made\n\nOn two cores."))
        self.assertLess(md.index("On two cores."), md.index("## Summary of claims"))
        code, _, err = run_report(self.results, "-o", out, "--preface", preface + ".missing")
        self.assertEqual(code, 2)
        self.assertIn("preface.md.missing: cannot read the preface", err)
        self.assertFalse(os.path.exists(os.path.join(out, "report.md")))
        for name in FIGURES:
            self.assertIn(f"](paper/figures/{name}.png)", md)
            self.assertTrue(os.path.isfile(os.path.join(out, "figures", name + ".png")), name)

    def test_bad_inputs(self):
        bad_run = "training.num_ferns=80_seed1.json"
        with open(os.path.join(self.results, "ferns", "runs", bad_run), "w") as f:
            f.write('{"run_id": "training.num_ferns=80_seed1", "metrics": {')  # truncated
        stale = os.path.join(self.results, "ferns", "runs", "training.num_ferns=40_seed1.json")
        with open(os.path.join(self.results, "ferns", "runs", "training.num_ferns=80_seed2.json")) as f:
            run = json.load(f)
        run["run_id"] = "training.num_ferns=40_seed1"
        run.setdefault("point", {})["training.num_ferns"] = 40
        with open(stale, "w") as f:
            json.dump(run, f)
        os.makedirs(os.path.join(self.results, "broken", "runs"))
        with open(os.path.join(self.results, "broken", "experiment.json"), "w") as f:
            f.write("not json")
        out = os.path.join(self.tmp, "out")
        code, _, err = run_report(self.results, "-o", out)
        self.assertEqual(code, 0, err)
        self.assertIn(f"ferns/runs/{bad_run}", err)
        self.assertIn("broken/experiment.json", err)
        self.assertNotIn("Traceback", err)
        md = read(os.path.join(out, "report.md"))
        self.assertIn(f"`ferns/runs/{bad_run}` could not be read", md)
        self.assertIn("broken/experiment.json: cannot read", md)
        # A run file of an earlier plan (K = 40 is not among experiment.json's runs) is
        # left out with a note, never mixed into the tables.
        self.assertIn("`ferns/runs/training.num_ferns=40_seed1.json` is not among", md)
        self.assertNotIn("| 40 |", md)
        # K = 80 keeps only seed 2; the other experiments are reported as before.
        self.assertIn("| 80 | 1 | 7.30 | 6.60 | 0.450 | 0.0940 | — |", md)
        self.assertIn("| ferns | refinement-2d | reproduced | refined 5.95 ± 0.21 px", md)
        self.assertFalse(os.path.exists(os.path.join(self.results, "report.md")))

        # One experiment folder given directly works; nothing readable is an error.
        code, _, err = run_report(os.path.join(self.results, "detail_pca"), "-o",
                                  os.path.join(self.tmp, "one"))
        self.assertEqual(code, 0, err)
        md = read(os.path.join(self.tmp, "one", "report.md"))
        self.assertIn("| detail_pca | refinement-2d | reproduced |", md)
        self.assertNotIn("ferns", md)
        code, _, err = run_report(os.path.join(self.results, "broken"), "-o",
                                  os.path.join(self.tmp, "none"))
        self.assertNotEqual(code, 0)
        self.assertIn("broken/experiment.json", err)
        self.assertNotIn("Traceback", err)


if __name__ == "__main__":
    unittest.main()
