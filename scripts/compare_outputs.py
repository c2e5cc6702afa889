#!/usr/bin/env python3
"""Compares two output trees of crease byte for byte, ignoring only what must differ
between two runs of the same command: timing and host fields.

Usage:
  compare_outputs.py REFERENCE OUTPUT            # the trees hold the same files, same bytes
  compare_outputs.py --subset REFERENCE OUTPUT   # every trusted file of OUTPUT equals REFERENCE's

What is ignored (scripts/kill_test.sh, README "Reliability: kill -9"):
  * files that only hold timings or logs: timings.csv, log.txt, *.log;
  * in JSON files, keys that hold a duration, a date or the machine, at any depth:
    IGNORED_JSON_KEYS below (e.g. "seconds", "timings", "machine", "host"), also as a
    part of a flattened key ("model.timing.PCA.mean_ms", "speed.fps") or with the
    suffix "_seconds" ("stage_seconds");
  * in CSV tables, the columns so named;
  * in crease's binary containers (.cdm, .crig, …: an 8-byte magic "CREAS…", a version,
    a JSON header), the header's keys as in JSON files;
  * in Markdown reports, sections whose heading names time, timing or speed, and lines
    that state a duration ("… pairs, 2.6 s."): TIMING_HEADING, TIMING_LINE.
Everything else, binary or text, must be equal byte for byte.

--subset is the check after a kill: what a rerun would trust must be complete and right.
Trusted is every file except temporaries (".NAME.tmp-HOST-PID" files and folders and
what they hold) and an experiment stage folder (cache/KIND/KEY/) without its
completion marker stage.json, which the runner deletes and rebuilds.
"""
import csv
import io
import json
import os
import re
import sys

IGNORED_FILES = {"timings.csv", "log.txt"}
IGNORED_SUFFIXES = (".log",)
IGNORED_JSON_KEYS = {
    "seconds", "timing", "timing_ms", "timings", "fps", "ms_per_frame", "setup_s",  # durations
    "detail_share", "tracking_share",  # shares of the time per frame
    "machine", "host", "hostname", "date", "started", "finished",  # where and when
}
TIMING_HEADING = re.compile(r"^#+ .*\b(time|timing|timings|speed)\b", re.IGNORECASE)
TIMING_LINE = re.compile(r"\b\d+(\.\d+)? ?(s|ms)\b")
TEMPORARY = re.compile(r"^\..+\.tmp-")


def ignored(rel):
    name = os.path.basename(rel)
    return name in IGNORED_FILES or name.endswith(IGNORED_SUFFIXES)


def untrusted(rel, root):
    parts = rel.split(os.sep)
    if any(TEMPORARY.match(p) for p in parts):
        return True
    # An experiment's stage folder: <out>/cache/KIND/KEY/...; trusted only with stage.json.
    if "cache" in parts:
        i = parts.index("cache")
        if len(parts) > i + 3:
            stage = os.path.join(root, *parts[: i + 3])
            return not os.path.isfile(os.path.join(stage, "stage.json"))
    return False


def files_of(root):
    out = set()
    for d, _, names in os.walk(root):
        for n in names:
            out.add(os.path.relpath(os.path.join(d, n), root))
    return out


def timing_key(key):
    return any(p in IGNORED_JSON_KEYS or p.endswith("_seconds") for p in key.split("."))


def strip_json(v):
    if isinstance(v, dict):
        return {k: strip_json(x) for k, x in v.items() if not timing_key(k)}
    if isinstance(v, list):
        return [strip_json(x) for x in v]
    return v


def normalised_json(data):
    try:
        return json.dumps(strip_json(json.loads(data)), sort_keys=True).encode()
    except ValueError:
        return data  # not JSON (a truncated file): compared as it is, and differs


def normalised_container(data):
    # magic (8 bytes), version (u32), header length (u64, little-endian), JSON header, arrays
    length = int.from_bytes(data[12:20], "little")
    if len(data) < 20 + length:
        return data
    return data[:12] + normalised_json(data[20:20 + length]) + data[20 + length:]


def normalised_markdown(data):
    kept, in_timing = [], False
    for line in data.decode("utf-8", "replace").splitlines():
        if line.startswith("#"):
            in_timing = bool(TIMING_HEADING.match(line))
        if not in_timing and not TIMING_LINE.search(line):
            kept.append(line)
    return "\n".join(kept).encode()


def normalised_csv(data):
    rows = list(csv.reader(io.StringIO(data.decode("utf-8", "replace"))))
    if not rows:
        return data
    keep = [i for i, name in enumerate(rows[0]) if not timing_key(name)]
    return "\n".join(",".join(r[i] for i in keep if i < len(r)) for r in rows).encode()


def normalised(path):
    with open(path, "rb") as f:
        data = f.read()
    if path.endswith(".json"):
        return normalised_json(data)
    if data.startswith(b"CREAS") and len(data) >= 20:
        return normalised_container(data)
    if path.endswith(".md"):
        return normalised_markdown(data)
    if path.endswith(".csv"):
        return normalised_csv(data)
    return data


def compare(ref, out, subset):
    ref_files = {f for f in files_of(ref) if not ignored(f)}
    out_files = {f for f in files_of(out) if not ignored(f)}
    if subset:
        out_files = {f for f in out_files if not untrusted(f, out)}
    problems = []
    if not subset:
        problems += [f"missing: {f}" for f in sorted(ref_files - out_files)]
    problems += [f"not in the reference: {f}" for f in sorted(out_files - ref_files)]
    for f in sorted(ref_files & out_files):
        if normalised(os.path.join(ref, f)) != normalised(os.path.join(out, f)):
            problems.append(f"differs: {f}")
    return problems


def main(argv):
    subset = "--subset" in argv
    args = [a for a in argv if a != "--subset"]
    if len(args) != 2:
        print(__doc__, file=sys.stderr)
        return 2
    problems = compare(args[0], args[1], subset)
    for p in problems:
        print(p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
