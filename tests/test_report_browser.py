"""The report opened in a real headless browser (Chromium): the figures and tables render, offline.

Skipped only when Chromium is not installed (``.ci/run`` installs Debian's chromium)."""
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from labtool.cli import main
from labtool.common.files import write_netcdf
from labtool.reports.synthetic import synthetic_measured

CHROMIUM = next((p for p in ("/usr/bin/chromium", shutil.which("chromium") or "", shutil.which("chromium-browser") or "")
                 if p and Path(p).exists()), None)

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")]


def _chromium(args, profile: Path, timeout=90):
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--disable-dev-shm-usage", f"--user-data-dir={profile}", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def report_html(tmp_path_factory):
    d = tmp_path_factory.mktemp("browser")
    ds = synthetic_measured(noise=0.03, gain=1.05, revolutions=3.4)
    ds["<i>evil"] = ("time", np.zeros(ds.sizes["time"]), {"units": "V", "long_name": "<script>document.title='pwned'</script>"})
    ds.attrs.update(test_id="T-BROWSER-7", operator="Ada <b>Operator</b>")
    write_netcdf(ds, d / "m.nc")
    html = d / "report.html"
    assert main(["report", str(d / "m.nc"), "--models", "kinematic", "-o", str(html)]) == 0
    return html


@pytest.mark.slow
def test_dom_has_the_tables_and_figures(report_html, tmp_path):
    res = _chromium(["--dump-dom", report_html.as_uri()], tmp_path / "profile")
    dom = res.stdout
    assert res.returncode == 0 and "</html>" in dom, res.stderr[-2000:]
    assert dom.count("<img") >= 5 and 'src="data:image/png;base64,' in dom
    assert '<table id="headline">' in dom and "kinematic, ω1 = ct." in dom and "kinematic, ω1 = var." in dom
    assert '<table id="metrics">' in dom and '<table id="events">' in dom
    # the title block comes first: before the verdict, every table and figure; provenance last
    block = dom.index('<table id="title-block"')
    assert block < dom.index('id="verdict-sentence"') < dom.index('<table id="headline">') < dom.index("<figure")
    assert dom.index("<figure") < dom.index('id="appendix"') < dom.index('id="provenance"')
    title = dom[block:dom.index("</table>", block)]
    assert "T-BROWSER-7" in title and "Ada &lt;b&gt;Operator&lt;/b&gt;" in title and "rpm" in title
    # every figure has its numbered caption
    n = dom.count("<figure")
    assert n >= 7 and all(f"Figure {k}. " in dom for k in range(1, n + 1))
    # the script in the file's attribute never ran (title unchanged) and shows as text
    assert "<title>labtool report" in dom and "pwned</title>" not in dom
    assert "&lt;script&gt;document.title" in dom


@pytest.mark.slow
def test_screenshot_shows_the_figures(report_html, tmp_path):
    """The first figure (omega2, measured vs model) follows the title block and the tables: the
    kinematic level's curves (Okabe-Ito orange for omega1 const, sky blue for var) must appear in
    the rendered pixels, and the verdict's box above them."""
    shot = tmp_path / "shot.png"
    res = _chromium([f"--screenshot={shot}", "--window-size=1200,3200", "--hide-scrollbars", report_html.as_uri()],
                    tmp_path / "profile")
    assert shot.exists(), res.stderr[-2000:]
    from matplotlib.image import imread
    img = (imread(str(shot))[..., :3] * 255).astype(int)
    assert img.shape[0] >= 3100 and img.shape[1] >= 1100

    def count(rgb, tol=40):
        return int(np.sum(np.all(np.abs(img - np.array(rgb)) < tol, axis=-1)))

    assert count((230, 159, 0), tol=25) > 300      # kinematic, omega1 constant
    assert count((86, 180, 233), tol=25) > 150     # kinematic, omega1 variable (dashed, on the same motion)
    # the verdict's box (light green: robust, yellow: cannot tell apart) is above the figures
    assert count((227, 244, 227), tol=4) + count((255, 244, 214), tol=4) > 2000
    # and the page is not blank: many distinct grey levels from text and tables
    assert len(np.unique(img.reshape(-1, 3)[:, 0])) > 50
