"""``labtool campaign run`` and ``labtool campaign report``: many operating points, one verdict.

``run plan.toml -o campaign/`` acquires, processes and compares every point of the plan, one
folder per point, resumably (rerun: finished points are kept, an unfinished one is redone), and
ends with the cross-point page. ``report campaign/ [measured.nc ...]`` rebuilds that page (and its
JSON and CSV) from a campaign folder and/or measured files. Exit 0: fine; 1: a threshold failed;
2: bad input (one line).
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import List, Optional

import typer

from labtool.options import given, op_option
from labtool.common.files import check_output_path

campaign_app = typer.Typer(
    help="Test campaigns: a plan of operating points acquired, processed and compared, one verdict across them.",
    no_args_is_help=True,
)


def register(app: typer.Typer) -> None:
    app.add_typer(campaign_app, name="campaign")


def _reporter():
    """The runner's progress as lines on stderr, one per step and point (a pipe or a log reads
    them as well as a terminal); on a terminal the acquisition's sample count runs live."""
    from labtool.campaign.runner import Reporter
    from labtool.common.errors import InputError
    from labtool.common.names import shown

    class Lines(Reporter):
        def __init__(self):
            self.tty = sys.stderr.isatty() and sys.stdin.isatty()
            self._last_live = 0.0

        def out(self, text: str) -> None:
            typer.echo(shown(text), err=True)

        def campaign_start(self, plan, folder, done):
            self.out(f"campaign {plan.doc.campaign.name}: {len(plan.points)} point(s) into {folder}"
                     + (f"; {done} already finished" if done else ""))

        def point_start(self, k, n, point):
            self.out(f"[{k}/{n}] {point.label()}")

        def step(self, point, step, status, detail=""):
            if status == "done":
                self.out(f"      {step}: done" + (f" ({detail})" if detail else ""))
            elif status == "running" and detail and self.tty:
                self.out(f"      {step}: {detail}")

        def point_done(self, k, n, point, wall_s, eta_s, worked):
            eta = "" if eta_s is None or k == n else f", about {eta_s:.0f} s left"
            how = f"finished in {wall_s:.1f} s" if worked else "finished earlier, kept"
            self.out(f"[{k}/{n}] {point.name} {how} ({k} of {n} points done{eta})")

        def warn(self, message):
            self.out(f"labtool: warning: {message}")

        def say(self, message):
            self.out(f"      {message}")

        def ask(self, message):
            if not self.tty:
                raise InputError("the plan asks the operator to confirm each speed (device.settle = \"prompt\") "
                                 "but there is no terminal; use settle = \"tacho\"")
            typer.prompt(message, default="", show_default=False, prompt_suffix=" ", err=True)

        def acquisition_progress(self, point, recorder, elapsed_s):
            if self.tty and elapsed_s - self._last_live >= 1.0:
                self._last_live = elapsed_s
                typer.echo(f"\r      acquire: {recorder.n_samples} samples, {elapsed_s:.0f} s", err=True, nl=False)

    return Lines()


@campaign_app.command("run")
def run(
    plan: Path = typer.Argument(..., help="campaign plan (TOML): device, calibration, test metadata, points, models"),
    output: Path = typer.Option(..., "-o", "--output", help="campaign folder (created; rerun into it to resume)"),
    redo: Optional[List[str]] = typer.Option(None, help="point name to record again although it is finished (repeatable)"),
    report: bool = typer.Option(True, "--report/--no-report", help="write the cross-point page at the end"),
    yes: bool = typer.Option(False, "--yes", "-y", help="run a campaign that records more than 10 min [s of the "
                             "stand] or writes more than 100 MB without asking (off a terminal it is refused without it)"),
) -> None:
    """Acquire, process and compare every point of the plan; one folder per point; resumable."""
    from labtool.campaign.plan import load_plan
    from labtool.campaign.runner import run_campaign
    from labtool.common import budget
    from labtool.output import terminal_confirm

    p = load_plan(plan)
    rep = _reporter()

    def check_work(seconds, nbytes, basis):
        budget.check_work("this campaign", seconds, nbytes, basis, terminal_confirm(), yes,
                          "record fewer points or revolutions (finished points are kept, a rerun resumes)")
    res = run_campaign(p, output, rep, redo or [], check_work)
    rep.out(f"campaign finished in {res.wall_s:.1f} s: {len(res.ran)} point(s) worked on, {len(res.kept)} kept")
    if report:
        _report([output], output / "campaign.html", output / "campaign.json", output / "campaign.csv", force=True)


@campaign_app.command("report")
def report_cmd(
    inputs: List[Path] = typer.Argument(..., help="campaign folder(s), point folders and/or measured.nc files"),
    output: Optional[Path] = typer.Option(None, "-o", "--output", help="HTML page to write (default: campaign.html "
                                                                        "in the campaign folder)"),
    json_path: Optional[Path] = typer.Option(None, "--json", help="JSON summary to write (default: beside the page)"),
    csv_path: Optional[Path] = typer.Option(None, "--csv", help="CSV table to write (default: beside the page)"),
    models: str = typer.Option("rigid,elastic", help="measured.nc inputs: models to compare, comma-separated"),
    omega1: str = typer.Option("const,var", "--omega1", help="measured.nc inputs: cam speed modes, comma-separated"),
    accuracy: str = typer.Option("fast", help="measured.nc inputs: solver preset (fast, standard, reference)"),
    revolutions: Optional[float] = typer.Option(None, help="measured.nc inputs: simulated cam revolutions [-] "
                                                "(default: labtool report's)"),
    restitution: Optional[float] = op_option("restitution", "measured.nc inputs"),
    contact_damping: Optional[float] = op_option("contact_damping", "measured.nc inputs"),
    contact_length_mm: Optional[float] = op_option("contact_length", "measured.nc inputs"),
    kc_factor: Optional[float] = op_option("kc_factor", "measured.nc inputs"),
    elastic_gap: Optional[str] = op_option("elastic_gap", "measured.nc inputs"),
    force: bool = typer.Option(False, help="overwrite existing output files"),
) -> None:
    """One page across the points: ratings against rpm per model, the closest model and where it
    changes, omega2/epsilon2 overlays per speed, events against speed, and a JSON/CSV table."""
    from labtool.common.errors import InputError

    if output is None:
        folders = [p for p in inputs if p.is_dir() and (p / "points").is_dir()]
        if len(folders) != 1:
            raise InputError("give -o PAGE.html (the default, campaign.html in the campaign folder, needs exactly "
                             "one campaign folder among the inputs)")
        output = folders[0] / "campaign.html"
    json_path = json_path or output.with_suffix(".json")
    csv_path = csv_path or output.with_suffix(".csv")
    from labtool.campaign.plan import check_compare

    cmp = check_compare({"models": _split(models), "omega1": _split(omega1), "accuracy": accuracy,
                         **({} if revolutions is None else {"revolutions": float(revolutions)})}, "options")
    _report(inputs, output, json_path, csv_path, force, cmp,
            given(restitution=restitution, contact_damping=contact_damping, contact_length=contact_length_mm,
                  kc_factor=kc_factor, elastic_gap=elastic_gap))


def _identification(inputs, records) -> dict | None:
    """The points' fits across the campaign: a joint fit in the campaign folder (fit.json, from
    'labtool fit points/*/measured.nc ... --shared backlash -o CAMPAIGN/fit.json'), else the points'
    own fit.json combined (labtool.identification.joint.campaign_identification)."""
    import json

    from labtool.common.errors import InputError
    from labtool.identification.joint import FORMAT, campaign_identification

    joint, source = None, ""
    for p in inputs:
        f = Path(p) / "fit.json"
        if Path(p).is_dir() and (Path(p) / "points").is_dir() and f.is_file():
            try:
                doc = json.loads(f.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise InputError(f"{f} is unreadable ({exc}); fit again with 'labtool fit ... -o {f} --force'") from None
            if not (isinstance(doc, dict) and doc.get("format") == FORMAT):
                raise InputError(f"{f} is not a joint fit of the campaign's measurements (format {FORMAT}); move it "
                                 "away, or make it with 'labtool fit POINTS/*/measured.nc --model ... --free ... "
                                 f"--shared ... -o {f}'")
            joint, source = doc, str(f)
    return campaign_identification([(r.name, r.fit) for r in records if r.fit is not None], joint, source)


def _split(text: str) -> list[str]:
    return [v.strip() for v in text.split(",") if v.strip()]


def _report(inputs, html: Path, json_path: Path, csv_path: Path, force: bool, compare=None,
            overrides: dict | None = None) -> None:
    from labtool.common.errors import InputError
    from labtool.campaign.report import collect_inputs, write_outputs

    outs = [html, json_path, csv_path]
    if len({p.resolve() for p in outs}) != len(outs):
        raise InputError("the HTML, JSON and CSV outputs must be different files")
    for p in outs:
        check_output_path(p, force)
    say = _reporter().say if sys.stderr.isatty() else None   # progress on a terminal, quiet when piped
    rep = collect_inputs(inputs, compare, overrides, page_base=html.parent, say=say)
    rep.identification = _identification(inputs, rep.records)
    write_outputs(rep, html, json_path, csv_path)
    from labtool.campaign.collect import undecided_with
    for r in rep.records:
        best, alike = r.summary.get("closest"), undecided_with(r)
        typer.echo(f"{r.name:24s} {r.rpm:6g} rpm  closest: {best}"
                   + (f" (cannot be told from {', '.join(alike)} here)" if alike else ""))
    for c in rep.changes:
        typer.echo(f"the closest model changes from {c['from']} ({c['from_rpm']:g} rpm) to {c['to']} "
                   f"({c['to_rpm']:g} rpm), {c['group']}")
    for g in (rep.identification or {}).get("groups", []):
        for key, p in g["parameters"].items():
            typer.echo(f"{key} ({g['model']} model, {len(p['files'])} points): {p['verdict']}")
    for n in rep.notes:
        typer.echo(f"note: {n}")
    typer.echo(f"wrote {html}, {json_path}, {csv_path}")
    if rep.passed is False:
        failed = [r.name for r in rep.records if r.summary.get("passed") is False]
        typer.echo(f"labtool: threshold checks failed at {len(failed)} point(s): {', '.join(failed)}", err=True)
        raise typer.Exit(1)
