"""The ``toolbox`` command: list, help, run, pipeline.

Exit codes: 0 success, 1 data error or failed algorithm (or any failed file of a batch),
2 usage error. Errors are one line on stderr naming the thing and what to do.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import textwrap

from . import __version__, kernels, progress, signals
from .errors import ToolboxError, UsageError

log = logging.getLogger("toolbox")


def _common(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("general options")
    g.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    g.add_argument("-q", "--quiet", action="store_true", help="no progress bars, warnings only")
    g.add_argument("--progress-json", action="store_true",
                   help="progress as one JSON line per update on stderr (for callers such as the QGIS provider)")
    g.add_argument("--arch", choices=kernels.ARCHES, default=None,
                   help="taichi architecture for kernels (default: $TOOLBOX_ARCH or auto: CUDA if present, else CPU)")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="toolbox",
        description="Plugin-based GIS processing toolbox for laser-scanning and photogrammetry data.",
    )
    p.add_argument("--version", action="version", version=f"toolbox {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    sp = sub.add_parser("list", help="list every algorithm and the plugin that provides it")
    sp.add_argument("--json", action="store_true", help="machine-readable output")
    _common(sp)

    sp = sub.add_parser("help", help="parameters, inputs, outputs and reference of an algorithm")
    sp.add_argument("--markdown", action="store_true", help="the inputs, outputs and parameters as Markdown tables")
    sp.add_argument("algorithm")
    sp.add_argument("--json", action="store_true", help="machine-readable output")
    _common(sp)

    sp = sub.add_parser("run", help="run an algorithm",
                        description="Run ALG on INPUT files. Several files (or a folder) for a single-input "
                                    "algorithm run as a batch into the output folder.")
    sp.add_argument("algorithm")
    sp.add_argument("inputs", nargs="*", metavar="INPUT")
    sp.add_argument("-o", "--output", required=True, help="primary output file, or a folder")
    sp.add_argument("--set", dest="params", action="append", default=[], metavar="NAME=VALUE",
                    help="set a parameter (repeatable)")
    sp.add_argument("--input", dest="named_inputs", action="append", default=[], metavar="NAME=PATH",
                    help="give the input NAME (see 'toolbox help ALG'); positional INPUTs fill the others in order")
    sp.add_argument("--output-path", dest="named_outputs", action="append", default=[], metavar="NAME=PATH",
                    help="path of a secondary output (default: beside the primary one); also asks for optional outputs")
    sp.add_argument("--preview", metavar="PNG", help="write the algorithm's preview image (if it has one) here")
    sp.add_argument("--crs", help="set or override the CRS of point inputs, e.g. EPSG:28992")
    sp.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    sp.add_argument("--json", action="store_true", help="print the run report as JSON")
    sp.add_argument("-j", "--jobs", "--workers", dest="jobs", type=int, default=None,
                    help="worker processes: files of a batch, or tiles of a survey, at once (default: all cores)")
    g = sp.add_argument_group("survey runs (all inputs are one survey, processed in tiles)")
    g.add_argument("--tile-size-m", type=float, default=None, metavar="S",
                   help="cut the survey into tiles of S metres on a fixed grid; -o is then an output folder")
    g.add_argument("--buffer-m", type=float, default=None, metavar="B",
                   help="points read around each tile (default: what the algorithm declares it needs)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="run the tiles on a dask.distributed cluster, e.g. tcp://10.0.0.5:8786 (default: local processes)")
    _common(sp)

    sp = sub.add_parser("qgis", help="the QGIS plugin: every algorithm in the Processing toolbox")
    q = sp.add_subparsers(dest="qgis_command", metavar="ACTION", required=True)
    qi = q.add_parser("install", help="copy the plugin into a QGIS profile and enable it (run again after "
                                      "installing a toolbox plugin)")
    qi.add_argument("--profile-dir", default=None, metavar="DIR",
                    help="the profile folder (the one holding python/plugins/); default: QGIS's default profile")
    _common(qi)
    qp = q.add_parser("package", help="the plugin as a zip for QGIS's 'Install from ZIP'")
    qp.add_argument("-o", "--output", required=True, metavar="ZIP")
    _common(qp)

    sp = sub.add_parser("pipeline", help="run a pipeline file (YAML or JSON)")
    sp.add_argument("file")
    sp.add_argument("--crs", help="set or override the CRS of point inputs")
    sp.add_argument("--overwrite", action="store_true", help="replace existing outputs")
    sp.add_argument("--json", action="store_true", help="print the reports as JSON")
    _common(sp)
    return p


def _pairs(items, what) -> dict:
    out = {}
    for item in items:
        if "=" not in item:
            raise UsageError(f"{what} {item!r} is not NAME=VALUE")
        k, v = item.split("=", 1)
        out[k.strip()] = v
    return out


def _setup(args) -> None:
    level = logging.WARNING
    if getattr(args, "verbose", 0) >= 2:
        level = logging.DEBUG
    elif getattr(args, "verbose", 0) == 1:
        level = logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)
    # laspy logs reader failures itself; the host reports them as one line
    logging.getLogger("laspy").setLevel(logging.DEBUG if level == logging.DEBUG else logging.CRITICAL)
    progress.set_quiet(getattr(args, "quiet", False) or getattr(args, "json", False))
    progress.set_json(getattr(args, "progress_json", False))
    kernels.set_arch(getattr(args, "arch", None))


def cmd_list(args) -> int:
    from .registry import registry

    reg = registry()
    if args.json:
        print(json.dumps({
            "algorithms": [{"id": a.id, "title": a.title, "plugin": a.plugin, "distribution": a.distribution,
                            "version": a.version} for a in sorted(reg.algorithms.values(), key=lambda a: a.id)],
            "broken": [vars(b) for b in reg.broken],
            "clashes": reg.clashes,
        }, indent=2))
        return 0
    rows = [(a.id, a.title, f"{a.plugin} ({a.distribution} {a.version})") for a in sorted(reg.algorithms.values(), key=lambda a: a.id)]
    w = max([len(r[0]) for r in rows] + [9])
    t = max([len(r[1]) for r in rows] + [5])
    print(f"{'ALGORITHM':<{w}}  {'TITLE':<{t}}  PLUGIN")
    for r in rows:
        print(f"{r[0]:<{w}}  {r[1]:<{t}}  {r[2]}")
    for aid, owners in sorted(reg.clashes.items()):
        print(f"{aid:<{w}}  CLASH: claimed by {' and '.join(owners)}")
    for b in reg.broken:
        print(f"BROKEN plugin {b.name} ({b.distribution} {b.version}): {b.reason}")
    return 0


def cmd_help(args) -> int:
    from .registry import registry

    alg = registry().get(args.algorithm)
    if args.json:
        print(json.dumps(alg.to_dict(), indent=2, default=str))
        return 0
    if args.markdown:
        from .docs import markdown

        print(markdown(alg), end="")
        return 0
    wrap = lambda s, ind="    ": textwrap.fill(s, 100, initial_indent=ind, subsequent_indent=ind)  # noqa: E731
    print(f"{alg.id} — {alg.title}")
    print(f"  provided by {alg.plugin} ({alg.distribution} {alg.version})\n")
    print(wrap(alg.description, "  "))
    if alg.reference:
        print("\nReference:\n" + wrap(alg.reference))
    print("\nInputs:")
    if not alg.inputs:
        print("    (none)")
    for i in alg.inputs:
        extra = ", one or more" if i.multiple else ""
        extra += ", optional" if i.optional else ""
        print(f"    {i.name} ({i.kind}{extra}): {i.description}")
    print("\nOutputs:")
    for o in alg.outputs:
        opt = ", optional: ask with --output-path" if o.optional else ""
        print(f"    {o.name} ({o.kind}, {o.extension}{opt}): {o.description}")
    print("\nParameters (--set NAME=VALUE):")
    for p in alg.parameters:
        unit = f" [{p.unit}]" if p.unit else ""
        print(f"    {p.name} ({p.type.__name__}{unit}) default {p.default if p.default is not None else 'auto'}; allowed {p.allowed()}")
        print(wrap(p.description, "        "))
    return 0


def _print_report(rep: dict) -> None:
    for name, info in rep["outputs"].items():
        if info.get("path") is None:
            continue
        detail = ""
        if info["kind"] == "points":
            detail = f"{info['n_points']:,} points"
        elif info["kind"] == "raster":
            detail = f"{info['width']}x{info['height']} cells of {info['cell_size']:g}"
        elif info["kind"] == "vector":
            detail = ", ".join(f"{k}: {v}" for k, v in info["layers"].items())
        print(f"  {name:<14} {info['path']}  ({detail})" if detail else f"  {name:<14} {info['path']}")
    if rep.get("stats", {}).get("note"):
        print(f"  note: {rep['stats']['note']}")
    for name, n in (rep.get("dropped_points") or {}).items():
        print(f"  note: {n:,} points of {rep.get('inputs', {}).get(name, name)} had a NaN or infinite coordinate and "
              "were left out")
    if rep.get("stats"):
        short = {k: v for k, v in rep["stats"].items() if isinstance(v, (int, float, str)) and k != "note"}
        if short:
            print("  " + ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in list(short.items())[:8]))


def cmd_run(args) -> int:
    from .registry import registry
    from .runner import is_batch, run_algorithm, run_batch

    if args.jobs is not None and args.jobs < 1:
        raise UsageError(f"-j {args.jobs}: give 1 or more worker processes (or leave -j out for one per core)")
    reg = registry()
    alg = reg.get(args.algorithm)
    params = _pairs(args.params, "--set")
    named = _pairs(args.named_outputs, "--output-path")
    if args.preview:
        if "preview" not in {o.name for o in alg.outputs}:
            raise UsageError(f"{alg.id} has no preview image; drop --preview")
        named["preview"] = args.preview
    if args.tile_size_m is None and (args.buffer_m is not None or args.scheduler):
        raise UsageError("--buffer-m and --scheduler belong to survey runs; add --tile-size-m")
    if args.tile_size_m is not None:
        return _run_survey(args, alg, params, named, reg)
    if is_batch(alg, args.inputs) and not args.named_inputs:
        if named:
            raise UsageError("--output-path/--preview name single files; a batch writes every output into the folder")
        rep = run_batch(alg.id, args.inputs, args.output, params, overwrite=args.overwrite, crs=args.crs,
                        jobs=args.jobs, reg=reg)
        if args.json:
            print(json.dumps(rep, indent=2, default=str))
        else:
            print(f"{alg.id}: {rep['n_done']} of {rep['n_files']} files done, {rep['n_failed']} failed "
                  f"({rep['timings_s']['total']:.1f} s, {rep['jobs']} jobs) -> {args.output}")
            for f in rep["failed"]:
                print(f"  FAILED {f['input']}: {f['error']}")
        return 1 if rep["n_failed"] else 0
    if args.named_inputs:
        from .runner import assign_inputs

        inputs = assign_inputs(alg, args.inputs, _pairs(args.named_inputs, "--input"))
    else:
        inputs = args.inputs
    rep = run_algorithm(alg.id, inputs, args.output, params, outputs=named,
                        overwrite=args.overwrite, crs=args.crs, reg=reg)
    if args.json:
        print(json.dumps(rep, indent=2, default=str))
    else:
        print(f"{alg.id} done in {rep['timings_s']['total']:.2f} s, wrote:")
        _print_report(rep)
    return 0


def _run_survey(args, alg, params, named, reg) -> int:
    from .survey import run_survey

    rep = run_survey(alg.id, args.inputs, args.output, params, tile_size_m=args.tile_size_m, buffer_m=args.buffer_m,
                     workers=args.jobs, scheduler=args.scheduler, outputs=named, overwrite=args.overwrite,
                     crs=args.crs, reg=reg)
    if args.json:
        print(json.dumps(rep, indent=2, default=str))
    else:
        s = rep["survey"]
        where = f"Dask cluster {rep['execution']['scheduler']}" if rep["execution"]["scheduler"] else \
            f"{rep['execution']['workers'] or 0} local workers"
        print(f"{alg.id} survey: {s['n_files']} files, {s['n_points']:,} points, {rep['n_tiles']} tiles of "
              f"{s['tile_size_m']:g} m with a {s['buffer_m']:g} m buffer; {rep['n_done']} done "
              f"({rep['n_skipped']} by an earlier run), {rep['n_failed']} failed ({rep['timings_s']['total']:.1f} s, {where})")
        for f in rep["failed"]:
            print(f"  FAILED tile {f['tile']}: {f['error']}")
        if rep["n_failed"]:
            print(f"  nothing merged; fix the cause and run the same command again: finished tiles are kept ({rep['manifest']})")
        for name, info in rep["outputs"].items():
            print(f"  {name:<14} {info['path']}")
    return 1 if rep["n_failed"] else 0


def cmd_pipeline(args) -> int:
    from . import pipeline

    stages = pipeline.load(args.file)
    rep = pipeline.run(stages, overwrite=args.overwrite, crs=args.crs)
    if args.json:
        print(json.dumps(rep, indent=2, default=str))
    else:
        for r in rep["stages"]:
            print(f"[{r['stage']}] {r['algorithm']} done in {r['timings_s']['total']:.2f} s")
            _print_report(r)
    return 0


def cmd_qgis(args) -> int:
    from . import qgis

    if args.qgis_command == "install":
        where = qgis.install(args.profile_dir)
        print(f"installed the QGIS plugin in {where} and enabled it; restart QGIS (Processing > Toolbox > "
              "Lidar toolbox), or run qgis_process list")
    else:
        print(f"wrote {qgis.package(args.output)}; in QGIS: Plugins > Manage and Install Plugins > Install from ZIP")
    return 0


COMMANDS = {"list": cmd_list, "help": cmd_help, "run": cmd_run, "pipeline": cmd_pipeline, "qgis": cmd_qgis}


def main(argv=None) -> int:
    signals.install()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.command:
        parser.print_help()
        return 2
    try:
        _setup(args)
        return COMMANDS[args.command](args)
    except BaseException as exc:  # noqa: BLE001 - every way out is one line and an exit code
        return _report_failure(exc, args)


def _report_failure(exc: BaseException, args) -> int:
    signum = signals.received()
    if signum is not None or isinstance(exc, (KeyboardInterrupt, signals.Terminated)):
        # whatever the interrupt turned into on its way up (lazrs: an I/O error), it was the signal
        signum = signum or (signal.SIGINT if isinstance(exc, KeyboardInterrupt) else exc.signum)
        what = "interrupted (Ctrl-C)" if signum == signal.SIGINT else f"terminated (signal {int(signum)})"
        print(f"toolbox: {what}; no output of the unfinished run was kept", file=sys.stderr)
        return signals.exit_code(signum)
    if isinstance(exc, ToolboxError):
        print(f"toolbox: error: {exc}", file=sys.stderr)
        return exc.exit_code
    if isinstance(exc, BrokenPipeError):  # output piped into head & co.
        return 0
    log.debug("unexpected error", exc_info=True)
    name = getattr(args, "algorithm", None) if args.command == "run" else None
    where = f"algorithm {name!r} failed" if name else f"{args.command} failed"
    if isinstance(exc, SystemExit):  # a plugin called sys.exit()
        detail = f"it called sys.exit({exc.code!r})"
    else:
        detail = f"{type(exc).__name__}: {' '.join(str(exc).split())[:300]}"
    print(f"toolbox: error: {where}: {detail} (run with -vv for the traceback)", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
