"""`tactile-sl train`: render labelled glyph patches with the simulator and train the CNN."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import torch

from tactile_sl_common.safe_files import OutputError, atomic_path, check_output, write_text
from tactile_sl_decoder.classify.classifier import (
    ARCH,
    ARCH_DESCRIPTIONS,
    DEFAULT_THRESHOLD,
    default_weights_path,
)
from tactile_sl_decoder.cli.argtypes import number
from tactile_sl_decoder.tooling.training import (
    DEFAULT_PRIMITIVES,
    HELDOUT_KINDS,
    TRAIN_KINDS,
    Progress,
    model_card,
    render_dataset,
    save_blob,
    train,
)


def register(subparsers: Any, summary: str | None = None) -> None:
    """Add the ``train`` subcommand."""
    p = subparsers.add_parser(
        "train", help=summary,
        description="Render stereo frames with the simulator (random indenters and nuisances), "
        "extract glyphs, label them from the ground truth and train the glyph classifier. "
        "Held-out frames use other seeds and other indenter kinds. Writes the weights "
        "(default: the ones the package ships) and a model card next to them.")
    p.add_argument("--frames", type=number(int, 1, 100_000), default=160,
                   help="training stereo frames (default 160)")
    p.add_argument("--val-frames", type=number(int, 1, 100_000), default=24,
                   help="held-out stereo frames (default 24)")
    p.add_argument("--epochs", type=number(int, 1, 10_000), default=12,
                   help="passes over the data (default 12)")
    p.add_argument("--seed", type=number(int, 0, 2**31 - 1), default=1,
                   help="seed of data and training (default 1)")
    p.add_argument("--threshold", type=number(float, 0.0, 1.0), default=DEFAULT_THRESHOLD,
                   help=f"confidence threshold stored with the weights ({DEFAULT_THRESHOLD})")
    p.add_argument("--artwork", default=None,
                   help="artwork PNG the simulator renders (default: the installed one)")
    p.add_argument("--arch", choices=sorted(ARCH_DESCRIPTIONS), default=ARCH,
                   help=f"network (default {ARCH}): " + "; ".join(
                       f"{k}: {v}" for k, v in ARCH_DESCRIPTIONS.items()))
    p.add_argument("--threads", type=number(int, 1, 1024), default=1,
                   help="torch CPU threads (default 1)")
    p.add_argument("-o", "--output", type=Path, default=None,
                   help=f"weights file (default {default_weights_path()})")
    p.add_argument("--card", type=Path, default=None,
                   help="model card (default: <weights name>_card.md next to the weights)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Generate data, train, save weights and card; returns the exit status."""
    out = args.output or default_weights_path()
    card = args.card or out.with_name(out.stem + "_card.md")
    try:     # before minutes of rendering and training: can the results be written?
        check_output(out)
        check_output(card)
    except OutputError as exc:
        print(f"train: {exc}", file=sys.stderr)
        return 1



    if args.frames < 1 or args.val_frames < 1 or args.epochs < 1:
        print("train: --frames, --val-frames and --epochs must be >= 1", file=sys.stderr)
        return 2
    torch.set_num_threads(max(1, args.threads))
    start = time.monotonic()
    try:
        bar = Progress(args.frames + args.val_frames, "render")
        train_set = render_dataset(args.frames, args.seed, TRAIN_KINDS, None, args.artwork,
                                   progress=bar.update)
        val_set = render_dataset(args.val_frames, args.seed + 7919, HELDOUT_KINDS, None,
                                 args.artwork, progress=bar.update)
    except (ValueError, OSError) as exc:
        print(f"train: cannot render training data: {exc}", file=sys.stderr)
        return 1
    data_seconds = time.monotonic() - start
    result = train(train_set, val_set, len(DEFAULT_PRIMITIVES), list(DEFAULT_PRIMITIVES),
                   epochs=args.epochs, seed=args.seed, threshold=args.threshold, arch=args.arch,
                   meta={"seed": args.seed, "torch": str(torch.__version__),
                         "frames": args.frames, "val_frames": args.val_frames})
    try:
        with atomic_path(out) as tmp:
            save_blob(result.blob, tmp)
    except OSError as exc:
        print(f"train: cannot write {out}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    note = (f"Simulator frames (`tactile_sl_sim`, shipped artwork), both cameras: "
            f"{args.frames} training frames (seed {args.seed}, indenters "
            f"{', '.join(TRAIN_KINDS)}) and {args.val_frames} held-out frames (seed "
            f"{args.seed + 7919}, indenters {', '.join(HELDOUT_KINDS)}); 0-2 indenters per "
            "frame with random radius, depth, position, shear; random blur, read and shot "
            "noise, vignetting, light position, gradient, gamma, exposure and shadows (30 % "
            "harsh); on 60 % of the frames also the nuisances of real sensors (an object seen "
            "through the pad: dark, striped, noisy or printed; MJPEG quality 45-95, defocus, "
            "motion blur, exposure differing between the cameras and from frame to frame, "
            "dropout, wear, scratches, bubbles, dust; each on some of those frames) and a glyph "
            "spacing of 12-24 px. Glyphs found by `extract_symbols`, labelled by the nearest "
            "ground-truth cell within a quarter spacing (value read from the artwork); damaged "
            "glyphs (worn, scratched, under a bubble or dust) are left out. Training adds patch "
            "augmentation: rotation +-15 deg, scale +-15 %, anisotropy +-15 %, shear +-0.15, "
            "shift +-1.2 px, "
            "gamma, contrast, offset, blur, noise.")
    try:
        write_text(card, model_card(result, note, data_seconds, out.name))
    except OSError as exc:
        print(f"train: cannot write {card}: {exc.strerror or exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} ({out.stat().st_size} bytes) and {card}")
    print(f"held-out accuracy {100 * result.val_accuracy:.3f} % "
          f"(confident {100 * result.val_confident_accuracy:.3f} %, unknown "
          f"{100 * result.val_unknown_rate:.3f} %), data {data_seconds:.0f} s, "
          f"training {result.seconds:.0f} s")
    return 0
