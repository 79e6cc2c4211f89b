"""``labtool devices``: what can record here: the simulated stand, and what NI-DAQmx sees."""
from __future__ import annotations

import json as jsonlib

import typer

from labtool.common.errors import InputError


def register(app: typer.Typer) -> None:
    app.command("devices")(devices)


def devices(json: bool = typer.Option(False, "--json", help="print one JSON object on stdout")) -> None:
    """List the devices acquire can use: the simulated stand, and every NI-DAQmx device (real or
    NI MAX simulated) with its AI channels, ranges and maximum rate; says why when NI-DAQmx is absent."""
    from labtool.acquisition.nidaqmx_driver import list_devices

    try:
        ni, ni_error = list_devices(), ""
    except InputError as exc:
        ni, ni_error = [], str(exc)
    if json:
        typer.echo(jsonlib.dumps({"sim": {"device": "sim", "available": True}, "nidaqmx": ni,
                                  "nidaqmx_error": ni_error or None}))
        return
    typer.echo("sim: the simulated stand (--device sim), always available")
    if ni_error:
        typer.echo(f"NI-DAQmx: not available: {ni_error}")
        return
    if not ni:
        typer.echo("NI-DAQmx: driver found, no devices (add a simulated one in NI MAX or with nidaqmxconfig; "
                   "see docs/acquisition.md)")
        return
    typer.echo(f"NI-DAQmx driver {ni[0]['driver']}: {len(ni)} device(s)")
    for d in ni:
        sim = " (simulated)" if d.get("simulated") is True else ""
        chans = d["ai_channels"]
        span = f"{chans[0]} .. {chans[-1]}" if len(chans) > 1 else (chans[0] if chans else "none")
        typer.echo(f"  {d['name']}: {d.get('product_type')}{sim}, serial {d.get('serial_num')}, "
                   f"{len(chans)} AI channels ({span}), max {d.get('ai_max_single_chan_rate_hz')} S/s, "
                   f"ranges {', '.join(d.get('ai_ranges_v') or ['-'])} V")
        if chans:
            typer.echo(f"    use: --device nidaqmx:{chans[0]}" + (f":{chans[min(2, len(chans) - 1)].rsplit('ai', 1)[-1]}"
                                                                   if len(chans) > 1 else ""))
