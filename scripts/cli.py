"""``eyemech``: list, run and sweep scenes (design brief §4).

    eyemech list [-v]
    eyemech run NAME [--config F.toml] [--set k=v ...] [--out DIR] [--json] [--vtx]
                     [--checkpoint-every N|Tm] [--resume DIR]
    eyemech run NAME --help          (the scene's parameters by group, with units and defaults)
    eyemech sweep NAME --grid k=v1,v2 [--grid ...] --out DIR [--ranks-per-case R] [--resume]
                       [--fields] [--pictures]
    eyemech study NAME|all|list [--quick] [--out DIR]
    eyemech bench NAME [--set KEY=VALUE ...] [--out docs/bench]

Exit codes: 0 done, 2 bad input (nothing solved, nothing written), 3 the solve
failed (the last converged state and results.json with status "failed" are kept),
4 a sweep or study ended but some of its cases failed (sweep.csv or the study's
table says which), 130 / 143
stopped by SIGINT / SIGTERM after writing a checkpoint (128 + the signal number;
continue with ``eyemech run NAME --resume DIR``), 1 an unexpected error (under MPI
on one rank: its traceback, then MPI_Abort ends the job).
"""

from __future__ import annotations

import argparse
import errno
import json
import logging
import os
import sys
import tempfile
import time
from pathlib import Path

EXIT_ERROR = 1
EXIT_BAD_INPUT = 2
EXIT_SOLVE_FAILED = 3
EXIT_CASES_FAILED = 4  # a sweep ran to its end, but some cases failed or raised
EXIT_INTERRUPTED_BASE = 128  # + the signal number, as a shell reports a signal


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="eyemech", description=__doc__.split("\n\n")[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log Newton progress")
    sub = parser.add_subparsers(dest="command", required=True)

    p_list = sub.add_parser("list", help="scenes and benchmarks, one line each")
    p_list.add_argument("-v", "--verbose", action="store_true", help="with their parameters")
    p_list.add_argument("--markdown", action="store_true",
                        help="parameter tables in Markdown (docs/parameters.md)")

    def common(p):
        p.add_argument("name", help="scene or benchmark (see 'eyemech list'); 'eyemech "
                       f"{p.prog.split()[-1]} NAME --help' lists its parameters by group")
        p.add_argument("--config", help="TOML file with parameter values")
        p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                       help="override one parameter (repeatable)")
        p.add_argument("--petsc", action="append", default=[], metavar="OPTION=VALUE",
                       help="PETSc option for the Newton solver, e.g. snes_linesearch_type=bt")
        p.add_argument("--factorisation", choices=("auto", "lu", "ldlt"), default="auto",
                       help="the direct solver's factorisation: MUMPS LU, MUMPS LDLᵀ (symmetric "
                            "Jacobians only), or auto: the scene's choice, LU unless LDLᵀ was "
                            "measured to pay (docs/atlas/peer-comparison.md)")
        p.add_argument("--quiet", action="store_true", help="no progress bar")
        p.add_argument("--no-fields", action="store_true",
                       help="do not write fields (.vtu + .pvd, or .bp with --vtx)")
        p.add_argument("--vtx", action="store_true",
                       help="also write the fields as ADIOS2 VTX (.bp, in parallel, for "
                            "ParaView with ADIOS2) beside the .vtu + .pvd (pyvista and ParaView)")
        p.add_argument("--no-pictures", action="store_true", help="do not render PNG pictures")
        p.add_argument("--checkpoint-every", default="10m", metavar="N|Tm",
                       help="write a checkpoint every N steps or T minutes (10m; 0 = only on "
                            "SIGINT/SIGTERM); kept in OUT/checkpoints/")

    p_run = sub.add_parser("run", help="run one scene")
    common(p_run)
    p_run.add_argument("--out", help="output folder (default results/NAME)")
    p_run.add_argument("--json", action="store_true",
                       help="print results.json as the last line on stdout")
    p_run.add_argument("--resume", metavar="DIR",
                       help="continue from the last checkpoint in DIR (a run's output folder; "
                            "its parameters are used; the output goes to DIR unless --out)")

    p_sweep = sub.add_parser("sweep", help="parameter study over a grid")
    common(p_sweep)
    p_sweep.add_argument("--grid", action="append", default=[], required=True,
                         metavar="KEY=V1,V2,...", help="values of one parameter (repeatable)")
    p_sweep.add_argument("--out", required=True, help="output folder (sweep.csv, case_NNNN/)")
    p_sweep.add_argument("--ranks-per-case", type=int, default=1)
    p_sweep.add_argument("--resume", action="store_true", help="skip cases already finished")
    p_sweep.add_argument("--json", action="store_true", help="print the rows as JSON")
    p_sweep.add_argument("--fields", action="store_true",
                         help="write each case's fields (off by default in a sweep)")
    p_sweep.add_argument("--pictures", action="store_true",
                         help="render each case's PNG pictures (off by default in a sweep)")
    p_study = sub.add_parser("study", help="accuracy-vs-cost and stability studies (CSV + PNG)")
    p_study.add_argument("name", help="study name, or 'all' (see 'eyemech study list')")
    p_study.add_argument("--out", help="output folder (default docs/studies; with --quick "
                         "results/studies-quick, so coarse charts never replace the atlas's)")
    p_study.add_argument("--quick", action="store_true", help="coarse settings (for tests)")
    p_bench = sub.add_parser("bench", help="time a scene at its benchmark size (table in --out)")
    p_bench.add_argument("name", help="scene name")
    p_bench.add_argument("--out", default="docs/bench", help="output folder")
    p_bench.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                         help="override one parameter on top of the scene's benchmark settings "
                              "(repeatable; the row's settings column names them all)")
    parser.commands = {"run": p_run, "sweep": p_sweep}  # for `eyemech run NAME --help`
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    scene_help = _scene_help_request(argv)
    if scene_help is not None:
        return _scene_help(*scene_help)
    args = _parser().parse_args(argv)
    if args.command == "list" and not (args.verbose or args.markdown):
        return _list_from_source()
    # Imported here so that `eyemech --help` and `eyemech list` are instant.
    from mpi4py import MPI

    _only_rank_0_reports(MPI.COMM_WORLD.rank, args.verbose)

    from petsc4py import PETSc  # noqa: F401  (PETSc's own signal handlers, replaced below)

    from eyemech.problems.run.signals import stop_signals

    comm = MPI.COMM_WORLD
    # SIGINT/SIGTERM end a command with 130/143 on every rank, also one stuck in C
    # (problems/run/signals.py)
    with stop_signals(rank=comm.rank):
        return _command(args, comm)


def _command(args, comm) -> int:
    from eyemech import problems
    from eyemech.meshes import MeshError
    from eyemech.problems.run.checkpoint import CheckpointError, Interrupted
    from eyemech.problems.run.faults import describe_output_error, output_error
    from eyemech.problems.run.lockstep import RanksDiverged
    from eyemech.problems.run.parameters import ParameterError
    from eyemech.problems.solve.driver import SolveFailure

    say = (lambda *a, **k: print(*a, **k)) if comm.rank == 0 else (lambda *a, **k: None)
    try:
        _check_paths(args)
        if args.command == "list":
            if args.markdown:
                say(parameter_tables(problems.scenes()), end="")
                return 0
            return _list(problems, args.verbose, say)
        if args.command == "study":
            return _study(args, comm, say)
        if args.command == "bench":
            from eyemech.problems.run.bench import run_benchmark
            from eyemech.problems.run.parameters import parse_assignments

            row = run_benchmark(problems.get(args.name), Path(args.out), comm,
                                overrides=parse_assignments(args.sets))
            say(f"{args.name}: {row}")
            return 0
        scene = problems.get(args.name)
        overrides = _overrides(args)
        options = _options(args)
        if args.command == "run":
            return _run(scene, overrides, args, options, comm, say)
        return _sweep(scene, overrides, args, options, comm, say)
    except KeyError as err:
        say(f"eyemech: error: {err.args[0]}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (ParameterError, MeshError, CheckpointError) as err:
        say(f"eyemech: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Interrupted as err:
        say(f"eyemech: {err}", file=sys.stderr)
        return EXIT_INTERRUPTED_BASE + err.signum
    except SolveFailure as err:
        say(f"eyemech: solve failed: {err}", file=sys.stderr)
        return EXIT_SOLVE_FAILED
    except RanksDiverged as err:  # raised on every rank alike (problems/run/lockstep.py)
        say(f"eyemech: error: {err}", file=sys.stderr)
        return EXIT_ERROR
    except Exception as err:
        if comm.size == 1 and isinstance(err, OSError) and (
                output_error(err) or err.errno == errno.ENAMETOOLONG):
            say(f"eyemech: error: {describe_output_error(err)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        if comm.size == 1:
            raise
        # an error on one rank would leave the others waiting in a collective call
        from eyemech.problems.run.faults import abort

        abort(comm)


# what the run adds below its output folder at most (case_NNNN/checkpoints/.tmp_ckpt_NNNNNN/
# rank_NNNN.npz and the like): a folder whose path leaves less room is refused
PATH_ROOM = 100


def _path_problem(path: str) -> str | None:
    """Why ``path`` cannot be used on this system (a name or the whole path too long)."""
    absolute = os.path.abspath(path)
    try:
        name_max = os.pathconf("/", "PC_NAME_MAX")
        path_max = os.pathconf("/", "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    for part in absolute.split(os.sep):
        if len(os.fsencode(part)) > name_max:
            return (f"{path[:40]}...: a name of {len(os.fsencode(part))} bytes "
                    f"({part[:24]}...); the file system allows {name_max}")
    if len(os.fsencode(absolute)) + PATH_ROOM > path_max:
        return (f"{absolute[:40]}...: a path of {len(os.fsencode(absolute))} bytes; the system "
                f"allows {path_max}, and the run's own files need {PATH_ROOM} more")
    return None


def _check_paths(args) -> None:
    """--out, --resume and --config usable as paths at all, before anything is read or
    written (exit 2 naming the option)."""
    from eyemech.problems.run.parameters import ParameterError

    for key in ("out", "resume", "config"):
        value = getattr(args, key, None)
        if isinstance(value, str) and value:
            why = _path_problem(value)
            if why:
                raise ParameterError(f"--{key}", why)


def _scene_help_request(argv: list[str]) -> tuple[str, str] | None:
    """(command, scene) for ``eyemech run|sweep NAME ... --help``, else None (argparse's help)."""
    words = [w for w in argv if w not in ("-v", "--verbose")]
    if len(words) < 3 or words[0] not in ("run", "sweep") or words[1].startswith("-"):
        return None
    return (words[0], words[1]) if {"-h", "--help"} & set(words[2:]) else None


def _scene_help(command: str, name: str) -> int:
    """The command's options, then the scene's parameters by group with type, default,
    unit and meaning (what ``--set`` and ``--config`` accept)."""
    import shutil
    import textwrap

    parser = _parser()
    lines = [parser.commands[command].format_help()]
    from eyemech import problems
    from eyemech.problems.run.parameters import groups

    try:
        scene = problems.get(name)
    except KeyError as err:
        print(f"eyemech: error: {err.args[0]}", file=sys.stderr)
        return EXIT_BAD_INPUT
    width = max(80, min(shutil.get_terminal_size((100, 24)).columns, 120))
    lines.append(f"{scene.name}: {scene.summary}\n\nparameters (--set KEY=VALUE, or KEY = VALUE "
                 f"in --config FILE.toml; all scenes: docs/parameters.md):")
    for group, rows in groups(scene.parameters).items():
        lines.append(f"\n  {group}:")
        for key, kind, default, unit, text in rows:
            lines.append(f"    {key} = {default!s}" + (f" {unit}" if unit else "") + f"  ({kind})")
            lines.append(textwrap.fill(text, width, initial_indent=" " * 8,
                                       subsequent_indent=" " * 8))
    _write_out("\n".join(lines) + "\n")
    return 0


def _write_out(text: str) -> None:
    """Standard output for a reader that may stop early (``eyemech run NAME --help | head``):
    the rest is dropped quietly. The scenes' imports start PETSc, whose handler turns
    SIGPIPE into an abort (exit 15, "Caught signal number 13"), so Python's own is put back
    first: the signal ignored, the write raising BrokenPipeError."""
    import os
    import signal

    signal.signal(signal.SIGPIPE, signal.SIG_IGN)
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())


def _only_rank_0_reports(rank: int, verbose: bool) -> None:
    """Log records and Python warnings from rank 0 only: every rank runs the same code,
    so the others would repeat each line (a step cut under -v, a missing checkpoint, a
    library's DeprecationWarning) once per rank. Errors are still logged on every rank:
    they can be one rank's own."""
    level = logging.INFO if verbose else logging.WARNING
    logging.basicConfig(level=level if rank == 0 else logging.ERROR,
                        format="%(levelname)s %(message)s", stream=sys.stderr, force=True)
    if rank != 0:
        import warnings

        warnings.simplefilter("ignore")


def _list_from_source() -> int:
    """Names, kinds and summaries read with ast (:mod:`eyemech.scripts.catalogue`): no
    DOLFINx, PETSc or MPI import. Under mpiexec only the first rank prints."""
    import os

    from eyemech.scripts.catalogue import scene_catalogue

    rank = next((os.environ[k] for k in ("PMI_RANK", "OMPI_COMM_WORLD_RANK") if k in os.environ), "0")
    if rank == "0":  # `eyemech list | head`: the reader may stop early
        _write_out("".join(f"{entry.name:24s} {entry.kind:10s} {entry.summary}\n"
                           for entry in scene_catalogue()))
    return 0


def _list(problems, verbose: bool, say) -> int:
    from eyemech.problems.run.parameters import groups

    for name, scene in problems.scenes().items():
        say(f"{name:24s} {scene.kind:10s} {scene.summary}")
        if verbose:
            for group, rows in groups(scene.parameters).items():
                say(f"  {group}:")
                for key, kind, default, unit, text in rows:
                    say(f"    {key:20s} {kind:14s} {default!s:12s} {unit:8s} {text}")
    return 0


def _study(args, comm, say) -> int:
    from eyemech.problems.studies import studies

    known = studies()
    if args.name == "list":
        for name, study in known.items():
            say(f"{name:32s} {study.summary}")
        return 0
    chosen = list(known) if args.name == "all" else [args.name]
    for name in chosen:
        if name not in known:
            raise KeyError(f"unknown study '{name}'; known: {', '.join(sorted(known))}")
    from eyemech.problems.studies import record

    out = Path(args.out or ("results/studies-quick" if args.quick else "docs/studies"))
    began = time.perf_counter()
    failed = []
    for name in chosen:
        start = time.perf_counter()
        with record(known[name], args.quick) as done:
            files = known[name].run(out=out, quick=args.quick, comm=comm)
        say(f"{name}: wrote {', '.join(str(f) for f in files)} "
            f"({time.perf_counter() - start:.0f} s)")
        # rank 0 writes the tables: it alone knows the failed cases
        done.failed = comm.bcast(done.failed if comm.rank == 0 else None, root=0)
        if done.failed:
            failed.append(name)
            say(f"eyemech: study {name}: {len(done.failed)} of {done.cases} cases failed: "
                f"{'; '.join(done.failed)}", file=sys.stderr)
    if len(chosen) > 1:
        say(f"{len(chosen)} studies in {time.perf_counter() - began:.0f} s"
            + (f"; cases failed in {', '.join(failed)}" if failed else ""))
    return EXIT_CASES_FAILED if failed else 0


def parameter_tables(scenes: dict) -> str:
    """Every scene's parameters as Markdown by group (the source of docs/parameters.md)."""
    from eyemech.problems.run.parameters import groups

    lines = ["# Scene parameters", "",
             "Generated by `eyemech list --markdown` from the parameter dataclasses; "
             "`--set key=value` and TOML configs use these keys.", ""]
    for name, scene in scenes.items():
        lines += [f"## `{name}` ({scene.kind})", "", scene.summary, ""]
        for group, rows in groups(scene.parameters).items():
            lines += [f"**{group}**", "", "| key | type | default | unit | meaning |",
                      "|---|---|---|---|---|"]
            for key, kind, default, unit, text in rows:
                lines.append(f"| `{key}` | {kind} | {default} | {unit} | {text} |".replace("\n", " "))
            lines.append("")
    return "\n".join(lines)


def _overrides(args) -> dict:
    from eyemech.problems.run.parameters import ParameterError, load_toml, parse_assignments

    try:
        overrides = load_toml(args.config) if args.config else {}
    except RecursionError:
        raise ParameterError("--config", f"{args.config} nests arrays or tables too deeply "
                             "to read") from None
    overrides.update(parse_assignments(args.sets))
    return overrides


def _options(args):
    from eyemech.problems.run.checkpoint import CheckpointOptions
    from eyemech.problems.run.context import RunOptions
    from eyemech.problems.run.parameters import (
        ParameterError,
        check_petsc_options,
        parse_assignments,
    )
    from eyemech.problems.run.petsc_output import for_trial
    from eyemech.problems.solve.driver import NewtonOptions

    newton = NewtonOptions(petsc={k.lstrip("-"): v for k, v in parse_assignments(args.petsc).items()},
                           factorisation=args.factorisation)
    # unknown names and unreadable values: exit 2 now; files of viewers go to the run's
    # folder (problems/run/petsc_output.py), so the trial writes them to a scratch folder
    with tempfile.TemporaryDirectory(prefix="eyemech-petsc-check-") as scratch:
        check_petsc_options(for_trial(newton.petsc, scratch))
    try:
        steps, minutes = CheckpointOptions.parse_every(args.checkpoint_every)
    except ValueError as err:
        raise ParameterError("--checkpoint-every", str(err)) from None
    # `run --resume DIR` names the folder; `sweep --resume` (a flag) resumes case by case
    resume = Path(args.resume) if args.command == "run" and args.resume else None
    checkpoint = CheckpointOptions(every_steps=steps, every_minutes=minutes, resume=resume)
    # a sweep writes fields and pictures only when asked (a case's are megabytes); a run
    # writes them unless told not to
    sweep = args.command == "sweep"
    fields = args.fields and not args.no_fields if sweep else not args.no_fields
    pictures = args.pictures and not args.no_pictures if sweep else not args.no_pictures
    return RunOptions(quiet=args.quiet, fields=fields, pictures=pictures, vtx=args.vtx,
                      newton=newton, checkpoint=checkpoint)


def _run(scene, overrides, args, options, comm, say) -> int:
    from eyemech.problems.run.parameters import build
    from eyemech.problems.solve.driver import SolveFailure

    if args.resume:
        overrides, finished = _resumed_parameters(scene, Path(args.resume), overrides, comm)
        if finished is not None:  # a finished run: its record, unchanged
            if args.json:
                say(json.dumps(finished))
            else:
                _summary(_Record(finished), Path(args.resume), say, scene.headline)
            return 0
    params = build(scene.parameters, overrides)  # raises before anything is created
    out = Path(args.out) if args.out else Path(args.resume) if args.resume \
        else Path("results") / scene.name
    from eyemech.problems.run.checkpoint import Interrupted

    try:
        result = scene.run(params, comm=comm, out=out, options=options)
    except (SolveFailure, Interrupted):
        if args.json:
            say(json.dumps(json.loads((out / "results.json").read_text())) if comm.rank == 0 else "")
        raise
    if args.json:
        say(json.dumps(result.as_json()))
    else:
        _summary(result, out, say, scene.headline)
    return 0


def _resumed_parameters(scene, folder: Path, overrides: dict, comm) -> tuple[dict, dict | None]:
    """The parameters of the run in ``folder`` (problems/run/identity.py: its run.json and
    its own checkpoints) and, when that run has finished, its results.json. --set/--config
    may repeat the run's values but not change them; no run in ``folder`` (no such folder,
    or nothing of eyemech's in it): exit 2."""
    from eyemech.problems.run.checkpoint import CheckpointError
    from eyemech.problems.run.identity import resume_plan
    from eyemech.problems.run.parameters import build

    plan, error = None, None
    if comm.rank == 0:  # rank 0 reads; its answer must not leave the others waiting
        try:
            plan = resume_plan(folder)
        except (OSError, ValueError) as err:
            error = str(err)
    plan, error = comm.bcast((plan, error), root=0)
    if error:
        raise CheckpointError(f"--resume {error}")
    if plan.scene != scene.name:
        raise CheckpointError(f"--resume {folder}: its run is of scene '{plan.scene}'")
    theirs = build(scene.parameters, plan.parameters).as_dict()
    mine = build(scene.parameters, {**plan.parameters, **overrides}).as_dict()
    changed = sorted(k for k in theirs if theirs[k] != mine[k])
    if changed:
        given = ", ".join(f"{k}={mine[k]!r} (the run has {theirs[k]!r})" for k in changed)
        raise CheckpointError(f"--resume {folder}: {given}; a resumed run keeps its "
                              "parameters (start a new run with --out for others)")
    if plan.finished is None and not plan.from_checkpoint:
        logging.getLogger("eyemech").warning(
            "no checkpoint of the run in %s: it starts again from the beginning, with its "
            "own parameters", folder)
    return dict(plan.parameters), plan.finished


class _Record:
    """A results.json as :func:`_summary` reads a Result."""

    def __init__(self, data: dict):
        self.scene, self.status = data.get("scene", "?"), data.get("status", "?")
        self.timings, self.mpi_size = data.get("timings") or {}, data.get("mpi_size", 1)
        self.quantities = data.get("quantities") or {}


def _summary(result, out: Path, say, headline=None) -> None:
    """The scene's headline (``Scene.headline``), then the result's scalar quantities; a
    staged scene's as a table, a column per stage (``after_<stage>`` groups), then the
    quantities that belong to no stage."""
    from eyemech.problems.run.results import stage_groups

    say(f"{result.scene}: {result.status} in {result.timings.get('total', 0):.1f} s "
        f"on {result.mpi_size} rank(s); results in {out}/results.json")
    for line in headline(result.quantities) if headline else []:
        say(f"  {line}")
    stages = stage_groups(result.quantities)
    staged: list[str] = []
    for group in stages.values():
        staged += [k for k, v in group.items() if _scalar(v) and k not in staged]
    if stages:
        say(f"  {'by stage':36s}" + "".join(f"{name.replace('_', ' '):>16s}" for name in stages))
        for key in staged:
            say(f"  {key:36s}" + "".join(f"{_shown(group.get(key, '—')):>16s}"
                                         for group in stages.values()))
        say(f"  at the end of the run (after {list(stages)[-1].removeprefix('after_')}):")
    for key, value in result.quantities.items():
        if _scalar(value) and key not in staged:
            say(f"  {key:36s} {_shown(value)}")


def _scalar(value) -> bool:
    return isinstance(value, (int, float, bool, str))


def _shown(value) -> str:
    return f"{value + 0.0:.6g}" if isinstance(value, float) else str(value)  # -0.0 as 0


def _sweep(scene, overrides, args, options, comm, say) -> int:
    from eyemech.problems.run.sweep import parse_grid, run_sweep

    rows = run_sweep(scene, overrides, parse_grid(args.grid), Path(args.out),
                     ranks_per_case=args.ranks_per_case, options=options, resume=args.resume,
                     comm=comm)
    if comm.rank == 0:
        failed = [r for r in rows if r.get("status") != "ok"]
        if args.json:
            say(json.dumps(rows))
        else:
            say(f"{len(rows)} cases, {len(failed)} failed; table in {Path(args.out) / 'sweep.csv'}")
        if failed:
            say(f"eyemech: {len(failed)} of {len(rows)} cases failed (cases "
                f"{', '.join(str(r['case']) for r in failed)}; see sweep.csv)", file=sys.stderr)
    failed_count = comm.bcast(len([r for r in rows if r.get("status") != "ok"])
                              if comm.rank == 0 else None, root=0)
    return EXIT_CASES_FAILED if failed_count else 0


if __name__ == "__main__":
    sys.exit(main())
