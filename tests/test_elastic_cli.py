"""The elastic model through the CLI contract: `labtool simulate --model elastic ... --json`."""
import json

import pytest
import xarray as xr

from labtool.cli import main


@pytest.mark.slow
def test_simulate_elastic_json_and_netcdf(tmp_path, capsys):
    out = tmp_path / "sim.nc"
    code = main(["simulate", "--model", "elastic", "--law", "sine", "--rpm", "180", "--fu", "65",
                 "--backlash-mm", "0.016", "--jt-factor", "1", "--omega1", "var", "--accuracy", "fast",
                 "--json", "-o", str(out)])
    assert code == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["model"] == "elastic"
    assert summary["jumps"] == 0 and summary["impacts"] == 0                       # Table 3 run 9
    assert summary["MR13D_max_Nm"] == pytest.approx(17.211, rel=0.10)
    assert summary["MR13D_min_Nm"] == pytest.approx(6.078, rel=0.10)
    assert summary["xel_min_mm"] == pytest.approx(-0.0015, rel=0.35)
    assert summary["percussion_max_Ns"] is None
    ds = xr.open_dataset(out, engine="h5netcdf")
    for name in ("x_el", "MR13D", "omega2", "epsilon2", "phi1"):
        assert ds[name].attrs["units"]
    ds.close()


@pytest.mark.parametrize("args", [["--backlash-mm", "-0.01"], ["--rpm", "-5"], ["--jt-factor", "0"],
                                  ["--contact-length-mm", "0"], ["--contact-length-mm", "-2"],
                                  ["--contact-length-mm", "nan"], ["--kc-factor", "-1"], ["--kc-factor", "0"],
                                  ["--contact-damping", "-0.5"], ["--elastic-gap", "open"]])
def test_bad_input_is_one_line_exit_2(args, capsys):
    code = main(["simulate", "--model", "elastic", *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("labtool: error:")
