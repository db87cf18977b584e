"""`tactile-sl pattern ...`: generate, verify, render, bound and benchmark M-array patterns."""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from tactile_sl_common.safe_files import OutputError, check_output, write_text
from tactile_sl_decoder.cli.argtypes import number
from tactile_sl_decoder.pattern import (
    Constraints,
    Pattern,
    PatternFormatError,
    load_pattern,
    parse_shape,
    save_pattern,
    verify_pattern,
)
from tactile_sl_decoder.pattern.artwork import render_png, render_svg
from tactile_sl_decoder.pattern.benchmark import run_benchmark
from tactile_sl_decoder.pattern.bounds import bound_report
from tactile_sl_decoder.pattern.fileio import DEFAULT_PITCH_M
from tactile_sl_decoder.pattern.generators import (
    DESCRIPTIONS,
    GENERATORS,
    GenerationFailed,
    generate,
)

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2

# Largest PNG `pattern render` draws (output pixels; rendering supersamples each one).
MAX_RENDER_PIXELS = 60_000_000


def _shape(text: str) -> tuple[int, int]:
    try:
        return parse_shape(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _constraints(args: argparse.Namespace) -> Constraints:
    return Constraints(args.symbols, args.window, args.min_hamming)


def _add_constraint_args(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--symbols", "-k", type=int, required=True, metavar="K",
                        help="alphabet size k (2..8)")
    parser.add_argument("--window", type=_shape, required=True, metavar="MxN",
                        help="window rows x cols, e.g. 3x3 (3..7 each)")
    parser.add_argument("--min-hamming", type=int, required=True, metavar="H",
                        help="minimum Hamming distance between any two windows (1 = unique)")


def _plain(value: Any) -> Any:
    """Convert numpy scalars and tuples so the YAML stays plain."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):
        return value.item()
    return value


def cmd_generate(args: argparse.Namespace) -> int:
    """Generate a pattern; non-zero exit (with the reason) when the budget ends first."""
    try:
        constraints = _constraints(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    rows, cols = args.size
    try:     # before the search: an output that cannot be written is said at once
        check_output(args.output)
        if args.certificate:
            check_output(args.certificate)
    except OutputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        result = generate(args.algorithm, constraints, rows, cols, seed=args.seed,
                          time_limit=args.time_limit, progress=not args.quiet, tidy=args.tidy)
    except GenerationFailed as exc:
        print(f"error: {args.algorithm} found no {rows}x{cols} pattern for "
              f"{constraints.describe()}: {exc.reason}", file=sys.stderr)
        return EXIT_FAILED
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    extra = {"generator": _plain({"algorithm": args.algorithm, "seed": args.seed,
                                  "seconds": round(result.seconds, 3), **result.stats})}
    pattern = Pattern(result.array, constraints, args.pitch_m, extra=extra)
    cert = verify_pattern(pattern)
    if not cert.valid:  # a generator bug: never write an invalid pattern
        print(cert.text(), file=sys.stderr)
        print("error: generated array failed verification; not written", file=sys.stderr)
        return EXIT_FAILED
    try:
        save_pattern(pattern, args.output)
        if args.certificate:
            write_text(args.certificate, cert.text())
    except OSError as exc:
        print(f"error: cannot write {args.output}: {exc}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {args.output}: {rows}x{cols}, {cert.windows} windows, minimum distance "
          f"{cert.min_distance} ({args.algorithm}, seed {args.seed}, {result.seconds:.2f} s)",
          file=sys.stderr)
    return EXIT_OK


def cmd_verify(args: argparse.Namespace) -> int:
    """Print the certificate; exit 1 if the pattern breaks its constraints, 2 if unreadable."""
    try:
        pattern = load_pattern(args.file, verify=False)
    except PatternFormatError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    cert = verify_pattern(pattern)
    text = cert.text()
    if not args.quiet:
        sys.stdout.write(text)
    if args.certificate:
        try:
            check_output(args.certificate, [args.file])
            write_text(args.certificate, text)
        except OSError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return EXIT_USAGE
    if not cert.valid:
        print(f"error: {args.file} is INVALID: {'; '.join(cert.problems)}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def cmd_render(args: argparse.Namespace) -> int:
    """Write SVG (mm) and/or PNG (+ sidecar) artwork of a pattern file."""
    if not args.svg and not args.png:
        print("error: give --svg OUT.svg and/or --png OUT.png", file=sys.stderr)
        return EXIT_USAGE
    if args.png and (args.dpi is None) == (args.pitch_px is None):
        print("error: --png needs exactly one of --dpi D or --pitch-px P", file=sys.stderr)
        return EXIT_USAGE
    try:
        pattern = load_pattern(args.file, verify=not args.allow_invalid_pattern)
        for out in (args.svg, args.png):
            if out:
                check_output(out, [args.file])
    except (PatternFormatError, OutputError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if args.png:
        pitch_px = (args.pitch_px if args.pitch_px is not None
                    else pattern.pitch_m * 1000.0 / 25.4 * args.dpi)
        width = math.ceil((pattern.cols - 1 + 2 * args.margin + 1) * pitch_px)
        height = math.ceil((pattern.rows - 1 + 2 * args.margin + 1) * pitch_px)
        if width * height > MAX_RENDER_PIXELS:
            print(f"error: the PNG would be about {width} x {height} px "
                  f"({width * height / 1e6:.0f} Mpx, limit {MAX_RENDER_PIXELS / 1e6:.0f} Mpx); "
                  "lower --dpi / --pitch-px or use --svg", file=sys.stderr)
            return EXIT_USAGE
    try:
        if args.svg:
            _render_atomic(args.svg, lambda path: render_svg(pattern, path,
                                                             margin_pitch=args.margin))
            print(f"wrote {args.svg}", file=sys.stderr)
        if args.png:
            side = _render_atomic(args.png, lambda path: render_png(
                pattern, path, dpi=args.dpi, pitch_px=args.pitch_px, margin_pitch=args.margin),
                sidecar=True)
            print(f"wrote {args.png} ({side['width_px']}x{side['height_px']} px, "
                  f"{side['pitch_px']:.2f} px per pitch) and {args.png}.yaml", file=sys.stderr)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (OSError, MemoryError) as exc:
        print(f"error: cannot render {args.svg or args.png}: "
              f"{getattr(exc, 'strerror', None) or exc or type(exc).__name__}", file=sys.stderr)
        return EXIT_FAILED
    return EXIT_OK


def _render_atomic(target: str, draw: Any, sidecar: bool = False) -> Any:
    """Draw into a temporary folder beside ``target``, then rename (with its sidecar)."""
    out = Path(target)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent if str(out.parent)
                                else "."))
    staged = tmp / out.name
    try:
        result = draw(staged)
        if sidecar:
            os.replace(str(staged) + ".yaml", str(out) + ".yaml")
        os.replace(staged, out)
        return result
    finally:
        for leftover in tmp.iterdir():
            leftover.unlink()
        tmp.rmdir()


def cmd_bound(args: argparse.Namespace) -> int:
    """Print code-size bounds and the largest arrays they allow."""
    try:
        constraints = _constraints(args)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    sys.stdout.write(bound_report(constraints))
    return EXIT_OK


def cmd_benchmark(args: argparse.Namespace) -> int:
    """Rerun the method's Table I with every generator; write a markdown table."""
    table = run_benchmark(seeds=args.seeds, time_limit=args.time_limit,
                          algorithms=args.algorithms, rows_filter=args.only,
                          progress=not args.quiet)
    if args.output:
        write_text(args.output, table)
        print(f"wrote {args.output}", file=sys.stderr)
    else:
        sys.stdout.write(table)
    return EXIT_OK


def register(subparsers: argparse._SubParsersAction, summary: str | None = None) -> None:
    """Add the ``pattern`` subcommand and its sub-subcommands."""
    parser = subparsers.add_parser(
        "pattern", help=summary,
        description="M-array patterns: every m x n window differs from every other in at "
                    "least h cells.")
    sub = parser.add_subparsers(dest="pattern_command", metavar="ACTION")
    parser.set_defaults(func=lambda _args: (parser.print_help(), EXIT_USAGE)[1])

    names = list(GENERATORS)
    algo_help = "; ".join(f"{n}: {DESCRIPTIONS[n]}" for n in names)
    gen = sub.add_parser("generate", help="generate a pattern file",
                         formatter_class=argparse.RawDescriptionHelpFormatter,
                         description="Generate a pattern. Algorithms:\n" + "\n".join(
                             f"  {n:14s} {DESCRIPTIONS[n]}" for n in names))
    _add_constraint_args(gen)
    gen.add_argument("--size", type=_shape, required=True, metavar="RxC",
                     help="array rows x cols")
    gen.add_argument("--algorithm", choices=names, default=names[0], metavar="NAME",
                     help=f"generator (default {names[0]}): {algo_help}")
    gen.add_argument("--seed", type=number(int, 0, 2**32 - 1), default=0,
                     help="random seed (default 0)")
    gen.add_argument("--time-limit", type=number(float, 0.001, 1e6),
                     default=60.0, metavar="SECONDS",
                     help="time budget (default 60)")
    gen.add_argument("--tidy", action="store_true",
                     help="auto/linear only: among offsets of the fold found, keep the one with "
                          "the fewest constant or repeated lines and draw a constant line with "
                          "value 1 (circles); still verified")
    gen.add_argument("--pitch-m", type=number(float, 1e-6, 0.1),
                     default=DEFAULT_PITCH_M,
                     help=f"symbol pitch in metres written to the file (default {DEFAULT_PITCH_M})")
    gen.add_argument("-o", "--output", required=True, metavar="FILE.yaml")
    gen.add_argument("--certificate", metavar="FILE.txt", help="also write the certificate")
    gen.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    gen.set_defaults(func=cmd_generate)

    ver = sub.add_parser("verify", help="verify a pattern file and print its certificate")
    ver.add_argument("file", metavar="FILE.yaml")
    ver.add_argument("--certificate", metavar="OUT.txt", help="also write the certificate")
    ver.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    ver.set_defaults(func=cmd_verify)

    ren = sub.add_parser("render", help="draw printable artwork (SVG in mm, PNG + sidecar)")
    ren.add_argument("file", metavar="FILE.yaml")
    ren.add_argument("--svg", metavar="OUT.svg")
    ren.add_argument("--png", metavar="OUT.png")
    ren.add_argument("--dpi", type=number(float, 1.0, 1e6), metavar="D",
                     help="PNG resolution (dots per inch)")
    ren.add_argument("--pitch-px", type=number(float, 1.0, 1e5), metavar="P",
                     help="PNG resolution as pixels per pitch instead of --dpi")
    ren.add_argument("--margin", type=number(float, 0.0, 100.0), default=1.5,
                     metavar="PITCHES",
                     help="margin around the outer cell centres, in pitches (default 1.5)")
    ren.add_argument("--allow-invalid-pattern", action="store_true",
                     help="draw a pattern that breaks its own constraints (experiments)")
    ren.set_defaults(func=cmd_render)

    bnd = sub.add_parser("bound", help="code-size bounds and the largest arrays they allow")
    _add_constraint_args(bnd)
    bnd.set_defaults(func=cmd_bound)

    ben = sub.add_parser("benchmark", help="rerun Table I: every generator on every row")
    ben.add_argument("--seeds", type=number(int, 1, 1000), default=3,
                     help="seeds per cell (default 3)")
    ben.add_argument("--time-limit", type=number(float, 0.001, 1e6),
                     default=10.0, metavar="SECONDS",
                     help="budget per run (default 10)")
    ben.add_argument("--algorithms", nargs="+", choices=names[1:], default=None,
                     help="generators to compare (default: all but auto)")
    ben.add_argument("--only", nargs="+", default=None, metavar="ROW",
                     help="run only rows whose label contains one of these strings")
    ben.add_argument("-o", "--output", metavar="OUT.md", help="write the table here")
    ben.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    ben.set_defaults(func=cmd_benchmark)
