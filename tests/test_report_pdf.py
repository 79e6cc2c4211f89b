"""The report's PDF, read back with poppler's tools as another program would: its text holds the
title block, Greek symbols and the verdict sentence; its fonts are a proportional family, embedded;
its pages are numbered. Skipped only when poppler-utils is not installed (.ci/run installs it)."""
import json
import re
import shutil
import subprocess

import pytest

from labtool.cli import main
from labtool.common.files import write_netcdf
from labtool.reports.synthetic import synthetic_measured

POPPLER = all(shutil.which(t) for t in ("pdftotext", "pdffonts", "pdfinfo"))
pytestmark = pytest.mark.skipif(not POPPLER, reason="poppler-utils is not installed (apt-get install poppler-utils)")


@pytest.fixture(scope="module")
def pdf(tmp_path_factory):
    d = tmp_path_factory.mktemp("pdf")
    ds = synthetic_measured(noise=0.03, gain=1.05, revolutions=3.4)
    ds.attrs.update(test_id="T-PDF-42", operator="Grace Hopper", sensor_serial="SN 1234")
    write_netcdf(ds, d / "m.nc")
    assert main(["report", str(d / "m.nc"), "--models", "kinematic", "-o", str(d / "r.html"), "--pdf",
                 str(d / "r.pdf"), "--json", str(d / "r.json")]) == 0
    return d


def _text(path) -> str:
    return subprocess.run(["pdftotext", "-layout", str(path), "-"], capture_output=True, text=True, check=True).stdout


@pytest.mark.slow
def test_the_pdf_text_holds_the_title_block_the_symbols_and_the_verdict(pdf):
    text = _text(pdf / "r.pdf")
    first = text.split("\f")[0]
    assert "T-PDF-42" in first and "Grace Hopper" in first and "SN 1234" in first
    assert "ω2" in first and "ε2" in first
    # the verdict sentence, the same words as the JSON's with its Greek symbols (pdftotext breaks the
    # lines where the page does)
    from labtool.reports.page import typeset
    sentence = typeset(json.loads((pdf / "r.json").read_text())["verdict"]["sentence"])
    assert "epsilon2" not in sentence and "w1 = " not in sentence
    flat = re.sub(r"\s+", " ", first)
    assert sentence in flat
    # nothing cut mid-number as the old monospace page did ('… 238.4, 258.')
    assert not re.search(r"\d,\s*$", first, re.M)


@pytest.mark.slow
def test_the_pdf_is_typeset_not_a_monospace_dump(pdf):
    fonts = subprocess.run(["pdffonts", str(pdf / "r.pdf")], capture_output=True, text=True, check=True).stdout
    rows = fonts.splitlines()[2:]
    assert rows, fonts
    names = [r.split()[0] for r in rows]
    assert any("DejaVuSans" in n for n in names) and not any("Mono" in n or "Courier" in n for n in names)
    assert all(" yes yes yes " in r for r in rows)           # embedded, subset, with a Unicode map
    info = subprocess.run(["pdfinfo", str(pdf / "r.pdf")], capture_output=True, text=True, check=True).stdout
    pages = int(re.search(r"Pages:\s+(\d+)", info).group(1))
    assert pages >= 3
    pages_text = _text(pdf / "r.pdf").split("\f")
    for k in range(1, pages + 1):
        assert f"page {k} of {pages}" in pages_text[k - 1]
    # numbered figure captions and the appendix
    whole = " ".join(pages_text)
    assert "Figure 1." in whole and "Appendix: provenance" in whole


@pytest.mark.slow
def test_the_page_and_the_pdf_say_the_same(pdf):
    """One model of the page, two renderers: the title block's rows and the figure captions are in both."""
    import html as html_lib
    page = html_lib.unescape(re.sub(r"<[^>]+>", " ", (pdf / "r.html").read_text()))
    text = re.sub(r"\s+", " ", _text(pdf / "r.pdf"))
    page = re.sub(r"\s+", " ", page)
    for caption in re.findall(r"Figure \d+\. [^<\n]+", (pdf / "r.html").read_text()):
        words = caption.split()[:4]
        assert " ".join(words) in text, caption
    for what in ("Test ID", "Operator", "Sensor, serial", "Load Fu", "Backlash j", "Models compared"):
        assert what in page and what in text, what
