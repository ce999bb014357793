"""`osnerf scenes`: list the built-in scenes, their objects and default demand."""

from __future__ import annotations

import argparse
import json
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")


def run(args: argparse.Namespace) -> int:
    from osnerf.scenes import DEFAULT_SCENE, SCENES

    rows = [
        {
            "name": s.name,
            "default": s.name == DEFAULT_SCENE,
            "objects": list(s.objects),
            "default_demand": list(s.default_demand),
            "description": s.description,
        }
        for s in SCENES.values()
    ]
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        sys.stdout.write("\n")
        return 0
    for r in rows:
        mark = " (default)" if r["default"] else ""
        print(f"{r['name']}{mark}: {r['description']}")
        print(
            f"    objects: {', '.join(r['objects'])}; default demand: "
            f"{', '.join(r['default_demand'])}"
        )
    return 0
