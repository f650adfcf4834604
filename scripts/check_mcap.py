#!/usr/bin/env python3
"""Checks MCAP files written by `smocap convert` with the official Python MCAP readers.

For each file (or every *.mcap under a folder given): lists the channels with their schemas;
checks that every channel is protobuf with a descriptor set as its schema and the expected
schema name (Foxglove's well-known names for /tf, /markers, /scene); decodes every message with
mcap-protobuf-support from the file's own descriptors; checks one message per frame on the
per-frame channels (the `frames` of the smocap.run metadata record) and one on /scene and
/smocap/subject; that the arrays agree with /smocap/subject (coordinates, marker points); that
every /tf message forms one tree rooted at `world`; the robot's /robot/tf (one per frame, one
tree rooted at `world`) and /robot/scene (once) when present; and, with the
`foxglove-schemas-protobuf` package installed, that every Foxglove message of the file's descriptors matches Foxglove's
official descriptor field by field (name, number, type, label, message type) and that every
Foxglove message parses with the official class without unknown fields. Exits 1 when any check
fails.

Setup (outside the repository):

    python3 -m venv /tmp/mcap-venv
    /tmp/mcap-venv/bin/pip install mcap mcap-protobuf-support foxglove-schemas-protobuf numpy
    /tmp/mcap-venv/bin/python scripts/check_mcap.py smocap-out
"""

import argparse
import importlib
import pathlib
import sys

from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from google.protobuf import descriptor_pb2, descriptor_pool

try:
    from google.protobuf.unknown_fields import UnknownFieldSet
except ImportError:  # older protobuf
    UnknownFieldSet = None

PER_FRAME = {
    "/smocap/state": "smocap.State",
    "/smocap/stats": "smocap.SolverStats",
    "/tf": "foxglove.FrameTransforms",
    "/markers": "foxglove.PointCloud",
}
ONCE = {"/scene": "foxglove.SceneUpdate", "/smocap/subject": "smocap.Subject", "/smocap/label_qc": "smocap.LabelQc"}
# Written only by trials with unfittable frames (issue 32).
OPTIONAL = {"/smocap/unfittable": "smocap.Unfittable"}
# Written by `smocap convert --robot` and `smocap retarget --into-mcap` (issue 31): when present,
# /robot/tf has one message per frame (a tree rooted at `world`) and /robot/scene one message.
ROBOT_PER_FRAME = {"/robot/tf": "foxglove.FrameTransforms"}
ROBOT_ONCE = {"/robot/scene": "foxglove.SceneUpdate"}
OPTIONAL.update(ROBOT_PER_FRAME)
OPTIONAL.update(ROBOT_ONCE)


def official_class(full_name):
    """The class of foxglove-schemas-protobuf for `foxglove.X`, or None when not installed."""
    name = full_name.split(".", 1)[1]
    try:
        return getattr(importlib.import_module(f"foxglove_schemas_protobuf.{name}_pb2"), name)
    except ImportError:
        return None


def compare_descriptors(ours, official, seen, errors):
    """Every field of `ours` (and of the foxglove messages it uses) as in `official`."""
    if ours.full_name in seen:
        return
    seen.add(ours.full_name)
    theirs = {f.name: f for f in official.fields}
    for f in ours.fields:
        o = theirs.get(f.name)
        if o is None:
            errors.append(f"{ours.full_name}.{f.name}: not in Foxglove's schema")
            continue
        mine = (f.number, f.type, f.is_repeated, f.message_type.full_name if f.message_type else None)
        want = (o.number, o.type, o.is_repeated, o.message_type.full_name if o.message_type else None)
        if mine != want:
            errors.append(f"{ours.full_name}.{f.name}: (number, type, repeated, message) {mine}, Foxglove has {want}")
        elif f.message_type and f.message_type.full_name.startswith("foxglove."):
            compare_descriptors(f.message_type, o.message_type, seen, errors)
    missing = sorted(set(theirs) - {f.name for f in ours.fields})
    if missing:
        errors.append(f"{ours.full_name}: Foxglove's fields {missing} are missing")


def check_tree(msg, seq, errors):
    parent = {}
    for t in msg.transforms:
        if t.child_frame_id in parent:
            errors.append(f"/tf seq {seq}: frame {t.child_frame_id!r} has two parents")
        parent[t.child_frame_id] = t.parent_frame_id
    for child in parent:
        f, hops = child, 0
        while f in parent and hops <= len(parent):
            f, hops = parent[f], hops + 1
        if f != "world":
            errors.append(f"/tf seq {seq}: frame {child!r} is not under 'world' (reaches {f!r})")
            return


def check(path, every):
    errors = []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            return [f"{path}: no summary section"]
        counts = summary.statistics.channel_message_counts if summary.statistics else {}
        print(f"{path}")
        print(f"  {'topic':<18} {'schema':<26} {'encoding':<9} {'schema enc.':<11} {'messages':>8}")
        topics = {}
        for cid, ch in sorted(summary.channels.items()):
            sc = summary.schemas.get(ch.schema_id)
            name = sc.name if sc else ""
            topics[ch.topic] = (name, sc)
            print(f"  {ch.topic:<18} {name:<26} {ch.message_encoding:<9} {sc.encoding if sc else '':<11} {counts.get(cid, 0):>8}")
            want = PER_FRAME.get(ch.topic) or ONCE.get(ch.topic) or OPTIONAL.get(ch.topic)
            if want and name != want:
                errors.append(f"{ch.topic}: schema name {name!r}, expected {want!r}")
            if ch.message_encoding != "protobuf" or (sc and sc.encoding != "protobuf"):
                errors.append(f"{ch.topic}: encoding {ch.message_encoding}/{sc.encoding if sc else None}")
        for t in list(PER_FRAME) + list(ONCE):
            if t not in topics:
                errors.append(f"channel {t} missing")
        # The file's Foxglove descriptors against the official ones.
        seen_msgs = set()
        for topic, (name, sc) in topics.items():
            cls = official_class(name) if name.startswith("foxglove.") else None
            if sc is None or cls is None:
                continue
            pool = descriptor_pool.DescriptorPool()
            for fd in descriptor_pb2.FileDescriptorSet.FromString(sc.data).file:
                pool.Add(fd)
            compare_descriptors(pool.FindMessageTypeByName(name), cls.DESCRIPTOR, seen_msgs, errors)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        run = meta.get("smocap.run", {})
        frames = int(run["frames"]) if "frames" in run else None
        decoded, seen, subject = 0, {}, None
        for schema, channel, message, msg in reader.iter_decoded_messages(log_time_order=False):
            decoded += 1
            k = seen.get(channel.topic, 0)
            seen[channel.topic] = k + 1
            if channel.topic == "/smocap/subject":
                subject = msg
            if k % every:
                continue
            cls = official_class(schema.name) if schema.name.startswith("foxglove.") else None
            if cls is not None:
                o = cls.FromString(message.data)
                if UnknownFieldSet is not None and len(UnknownFieldSet(o)):
                    errors.append(f"{channel.topic} seq {message.sequence}: unknown fields for Foxglove's {schema.name}")
            if channel.topic in ("/tf", "/robot/tf"):
                check_tree(msg, message.sequence, errors)
            if subject is not None and channel.topic == "/smocap/state" and len(msg.q) != len(subject.coordinates):
                errors.append(f"/smocap/state seq {message.sequence}: {len(msg.q)} q for {len(subject.coordinates)} coordinates")
            if subject is not None and channel.topic == "/markers" and len(msg.data) != 12 * len(subject.markers):
                errors.append(f"/markers seq {message.sequence}: {len(msg.data)} bytes for {len(subject.markers)} markers")
        total = sum(counts.values())
        size = pathlib.Path(path).stat().st_size
        per = f"{size / frames:.0f} bytes/frame" if frames else ""
        print(f"  decoded {decoded} of {total} messages; smocap.run frames = {frames}; {size} bytes, {per}")
        if decoded != total:
            errors.append(f"decoded {decoded} messages, the summary counts {total}")
        if frames is None:
            errors.append("no frames in the smocap.run metadata")
        else:
            for t in PER_FRAME:
                if seen.get(t, 0) != frames:
                    errors.append(f"{t}: {seen.get(t, 0)} messages for {frames} frames")
        for t in ONCE:
            if seen.get(t, 0) != 1:
                errors.append(f"{t}: {seen.get(t, 0)} messages, expected 1")
        if any(t in topics for t in list(ROBOT_PER_FRAME) + list(ROBOT_ONCE)):
            for t in ROBOT_PER_FRAME:
                if frames is not None and seen.get(t, 0) != frames:
                    errors.append(f"{t}: {seen.get(t, 0)} messages for {frames} frames")
            for t in ROBOT_ONCE:
                if seen.get(t, 0) != 1:
                    errors.append(f"{t}: {seen.get(t, 0)} messages, expected 1")
    return [f"{path}: {e}" for e in errors]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("paths", nargs="+", help="MCAP files, or folders searched for *.mcap")
    ap.add_argument("--every", type=int, default=1, help="check every Nth message of a channel in depth (default 1: all)")
    a = ap.parse_args()
    if official_class("foxglove.FrameTransforms") is None:
        print("note: foxglove-schemas-protobuf not installed; not compared with Foxglove's schemas", file=sys.stderr)
    files = []
    for p in map(pathlib.Path, a.paths):
        files.extend(sorted(p.rglob("*.mcap")) if p.is_dir() else [p])
    errors = []
    for f in files:
        errors.extend(check(f, max(1, a.every)))
    for e in errors:
        print(f"FAIL {e}", file=sys.stderr)
    print(f"{len(files)} files, {len(errors)} problems")
    return 1 if errors or not files else 0


if __name__ == "__main__":
    sys.exit(main())
