#!/usr/bin/env python3
"""Checks MCAP files written by `smocap convert` with the official Python MCAP reader.

For each file (or every *.mcap under a folder given): lists the channels with their schemas,
decodes every message (json.loads), checks that each channel's messages validate against the
JSON Schema stored in the file, that /smocap/state has one message per frame (the `frames` of
the smocap.run metadata record) and the same count as every other channel, that /tf and /scene
carry Foxglove's well-known schema names (foxglove.FrameTransforms, foxglove.SceneUpdate), and,
with --foxglove-schemas, that their messages validate against Foxglove's official JSON Schemas.
Exits 1 when any check fails.

Setup (outside the repository):

    python3 -m venv /tmp/mcap-venv && /tmp/mcap-venv/bin/pip install mcap jsonschema
    # Foxglove's official JSON Schemas ship in the npm package @foxglove/schemas:
    (cd /tmp && npm pack @foxglove/schemas@2 && tar xzf foxglove-schemas-*.tgz)
    /tmp/mcap-venv/bin/python scripts/check_mcap.py smocap-out --foxglove-schemas /tmp/package

--foxglove-schemas takes the unpacked npm package (read through `node`), or a folder of
<Name>.json files (e.g. foxglove-sdk's schemas/jsonschema).
"""

import argparse
import json
import pathlib
import subprocess
import sys

from mcap.reader import make_reader

try:
    import jsonschema
except ImportError:  # schema validation is skipped with a note
    jsonschema = None

FOXGLOVE = {"/tf": "foxglove.FrameTransforms", "/scene": "foxglove.SceneUpdate"}
OURS = {"/smocap/state": "smocap.State", "/smocap/residuals": "smocap.Residuals", "/smocap/stats": "smocap.SolverStats"}


def official_schemas(path):
    """Foxglove's JSON Schemas by full name (foxglove.X) from an npm package or a folder."""
    p = pathlib.Path(path)
    names = [n.split(".", 1)[1] for n in FOXGLOVE.values()]
    if (p / "package.json").is_file():
        js = "const s=require(%s);console.log(JSON.stringify({%s}))" % (
            json.dumps(str((p / "dist" / "jsonschema" / "index.js").resolve())),
            ",".join(f"{n}:s.{n}" for n in names),
        )
        got = json.loads(subprocess.run(["node", "-e", js], check=True, capture_output=True, text=True).stdout)
    else:
        got = {n: json.loads((p / f"{n}.json").read_text()) for n in names}
    return {f"foxglove.{n}": validator(s) for n, s in got.items()}


def validator(schema):
    cls = jsonschema.validators.validator_for(schema)
    return cls(schema)


def check(path, official, every):
    errors = []
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            return [f"{path}: no summary section"]
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        print(f"{path}")
        print(f"  {'topic':<20} {'schema':<26} {'encoding':<9} {'schema enc.':<11} {'messages':>8}")
        own = {}
        for cid, ch in sorted(summary.channels.items()):
            sc = summary.schemas.get(ch.schema_id)
            name = sc.name if sc else ""
            print(f"  {ch.topic:<20} {name:<26} {ch.message_encoding:<9} {sc.encoding if sc else '':<11} {counts.get(cid, 0):>8}")
            want = FOXGLOVE.get(ch.topic) or OURS.get(ch.topic)
            if want and name != want:
                errors.append(f"{ch.topic}: schema name {name!r}, expected {want!r}")
            if ch.message_encoding != "json" or (sc and sc.encoding != "jsonschema"):
                errors.append(f"{ch.topic}: encoding {ch.message_encoding}/{sc.encoding if sc else None}")
            if sc and jsonschema:
                own[ch.topic] = validator(json.loads(sc.data))
        for t in list(FOXGLOVE) + list(OURS):
            if t not in {c.topic for c in summary.channels.values()}:
                errors.append(f"channel {t} missing")
        meta = {}
        for m in reader.iter_metadata():
            meta[m.name] = m.metadata
        run = meta.get("smocap.run", {})
        frames = int(run["frames"]) if "frames" in run else None
        decoded, seen, bad = 0, {}, {}
        for _schema, channel, message in reader.iter_messages():
            try:
                v = json.loads(message.data)
            except ValueError as e:
                errors.append(f"{channel.topic} seq {message.sequence}: not JSON: {e}")
                continue
            decoded += 1
            k = seen.get(channel.topic, 0)
            seen[channel.topic] = k + 1
            if k % every:
                continue
            checks = [("file schema", own.get(channel.topic))]
            if channel.topic in FOXGLOVE and FOXGLOVE[channel.topic] in official:
                checks.append(("official schema", official[FOXGLOVE[channel.topic]]))
            for what, val in checks:
                if val is None:
                    continue
                err = next(iter(val.iter_errors(v)), None)
                if err is not None and bad.get((channel.topic, what), 0) < 3:
                    bad[(channel.topic, what)] = bad.get((channel.topic, what), 0) + 1
                    where = "/".join(str(x) for x in err.absolute_path)
                    errors.append(f"{channel.topic} seq {message.sequence}: {what}: {where}: {err.message[:200]}")
        total = sum(counts.values())
        print(f"  decoded {decoded} of {total} messages as JSON; smocap.run frames = {frames}")
        if decoded != total:
            errors.append(f"decoded {decoded} messages, the summary counts {total}")
        n_state = seen.get("/smocap/state", 0)
        if frames is None:
            errors.append("no frames in the smocap.run metadata")
        elif n_state != frames:
            errors.append(f"{n_state} state messages for {frames} frames")
        for t, n in seen.items():
            if n != n_state:
                errors.append(f"{t}: {n} messages, /smocap/state has {n_state}")
    return [f"{path}: {e}" for e in errors]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+", help="MCAP files, or folders searched for *.mcap")
    ap.add_argument("--foxglove-schemas", help="unpacked npm @foxglove/schemas, or a folder of <Name>.json")
    ap.add_argument("--every", type=int, default=1, help="validate every Nth message of a channel (default 1: all)")
    a = ap.parse_args()
    if a.foxglove_schemas and jsonschema is None:
        ap.error("--foxglove-schemas needs the jsonschema package")
    official = official_schemas(a.foxglove_schemas) if a.foxglove_schemas else {}
    if jsonschema is None:
        print("note: jsonschema not installed; messages are decoded but not validated", file=sys.stderr)
    elif not official:
        print("note: no --foxglove-schemas; /tf and /scene checked against the files' own schemas only", file=sys.stderr)
    files = []
    for p in map(pathlib.Path, a.paths):
        files.extend(sorted(p.rglob("*.mcap")) if p.is_dir() else [p])
    errors = []
    for f in files:
        errors.extend(check(f, official, max(1, a.every)))
    for e in errors:
        print(f"FAIL {e}", file=sys.stderr)
    print(f"{len(files)} files, {len(errors)} problems")
    return 1 if errors or not files else 0


if __name__ == "__main__":
    sys.exit(main())
