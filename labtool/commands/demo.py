"""``labtool demo``: the whole pipeline on the simulated stand and sample_data/.

Kinematics of the paper's mechanism at 180 rpm; the 16 runs of Table 1 against the paper's Table 3
(kinematic MR13D); the simulated stand records the paper's experiment; processing; the rigid and
elastic models against it in report.html (labtool/demo_steps.py). Ends by printing where the report
is and its headline figures; a step whose piece is missing is skipped and said.
"""
from __future__ import annotations

from pathlib import Path

import typer


def register(app: typer.Typer) -> None:
    app.command("demo")(demo)


def demo(
    output: Path = typer.Option(Path("demo_out"), "-o", "--output", help="folder for the demo's files"),
) -> None:
    """Run the demo pipeline and print where its results are."""
    import contextlib

    import matplotlib

    matplotlib.use("Agg")
    from labtool.common.files import staged_folder
    from labtool.demo_steps import run_demo

    shown_as = output.absolute()
    # every file is made in a hidden folder beside the output folder and moved in at the end:
    # a full disk, Ctrl-C or a failure leaves the output folder as it was
    with staged_folder(output) as stage, contextlib.chdir(stage):
        announce = run_demo(Path("."), shown_as=shown_as)
    announce()
