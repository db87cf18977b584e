"""``tactile-sl synth SCENES.yaml -o DIR``: render scenes into MCAP bags with ground truth.

Also ``tactile-sl synth --benchmark`` prints the renderer's stereo frame rate.
"""
from __future__ import annotations

import argparse
import os
import pathlib
import sys

from tactile_sl_sim.artwork import ArtworkError
from tactile_sl_sim.scenes import Scene, SceneError, load_scenes
from tactile_sl_sim.synth import Progress, RendererCache, benchmark, write_scene_bag


def register(subparsers: argparse._SubParsersAction, summary: str | None = None) -> None:
    """Add the ``synth`` subcommand."""
    p = subparsers.add_parser(
        "synth", help=summary,
        description="Render each scene of SCENES.yaml as a rosbag2-compatible MCAP bag "
        "DIR/<scene>.mcap with /tactile/{left,right}/{image_raw,camera_info} and "
        "/tactile/ground_truth/points; scenes with load contacts (known forces) add "
        "/tactile/ground_truth/{wrench,field,contact} in the pad frame (and "
        "/tactile/ground_truth/slip with friction). Deterministic: the same file gives the "
        "same bytes.")
    p.add_argument("scenes", nargs="?", help="scenes YAML file (see docs/camera.md)")
    p.add_argument("-o", "--output", default=".", help="output directory (default: .)")
    p.add_argument("--artwork", default=None,
                   help="artwork PNG with its .png.yaml sidecar (default: the installed "
                   "share/tactile_sl_sim/artwork/pattern.png)")
    p.add_argument("--only", action="append", default=[], metavar="NAME",
                   help="render only this scene (repeatable)")
    p.add_argument("--namespace", default="/tactile", help="topic namespace (default /tactile)")
    p.add_argument("--benchmark", nargs="?", type=int, const=30, default=None, metavar="N",
                   help="instead of writing bags, render N stereo frames (default 30) and "
                   "print frames per second")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``tactile-sl synth``."""
    cache = RendererCache(args.artwork)
    if args.benchmark is not None:
        return _benchmark(args, cache, benchmark)
    if not args.scenes:
        print("tactile-sl synth: a scenes file is required (or --benchmark)", file=sys.stderr)
        return 2
    try:
        scenes = load_scenes(args.scenes)
    except SceneError as exc:
        print(f"tactile-sl synth: {exc}", file=sys.stderr)
        return 2
    if args.only:
        unknown = sorted(set(args.only) - {s.name for s in scenes})
        if unknown:
            print(f"tactile-sl synth: no scene named {', '.join(unknown)} in {args.scenes}",
                  file=sys.stderr)
            return 2
        scenes = [s for s in scenes if s.name in args.only]
    out = pathlib.Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    progress = Progress(sum(s.frames for s in scenes))
    for scene in scenes:
        try:
            renderer = cache.get(scene)
        except (ArtworkError, ValueError) as exc:
            print(f"\ntactile-sl synth: scene {scene.name}: {exc}", file=sys.stderr)
            return 1
        path = out / f"{scene.name}.mcap"

        def frame_done(_index: int, name: str = scene.name) -> None:
            progress.update(1, name)

        write_scene_bag(scene, renderer, path, namespace=args.namespace, on_frame=frame_done)
        print(f"{path}: {scene.frames} frames, {os.path.getsize(path) / 1e6:.2f} MB",
              file=sys.stderr)
    return 0


def _benchmark(args: argparse.Namespace, cache: object, bench: object) -> int:
    scene = Scene(name="benchmark")
    try:
        renderer = cache.get(scene)  # type: ignore[attr-defined]
    except ArtworkError as exc:
        print(f"tactile-sl synth: {exc}", file=sys.stderr)
        return 1
    w, h = renderer.rig.params.width, renderer.rig.params.height
    flat = bench(renderer, args.benchmark, contacts=[])  # type: ignore[operator]
    contact = bench(renderer, args.benchmark)  # type: ignore[operator]
    print(f"renderer benchmark: {w}x{h} stereo, supersample {renderer.ss}x{renderer.ss}, images "
          f"+ ground truth, one thread, {args.benchmark} frames each")
    for name, (per_wall, per_cpu) in (("no contact", flat), ("sphere contact", contact)):
        print(f"  {name:15s} {per_cpu:6.1f} stereo frames per CPU second "
              f"({per_wall:.1f} per wall-clock second)")
    return 0
