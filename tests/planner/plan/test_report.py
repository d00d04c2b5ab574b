"""The plan's HTML report: figures on disk, escaping, schema check, and a real render in headless Chromium.

The browser test is never skipped: without Chromium it fails and says how to install it
(``.ci/run`` installs it from Debian's packages).
"""

import copy
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

import sim.uuv
from planner.plan.generate import GenerateConfig, generate
from planner.plan.report import _coordinates, write_report

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"
MISSION = EXAMPLES / "range2017.toml"


class _Tags(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs, self.links, self.scripts = [], [], 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a.get("src"))
        elif tag == "a":
            self.links.append(a.get("href"))
        elif tag == "script":
            self.scripts += 1


def _tags(page: str) -> _Tags:
    t = _Tags()
    t.feed(page)
    return t


@pytest.fixture(scope="module")
def mission():
    return sim.uuv.load_mission(MISSION)


@pytest.fixture(scope="module")
def planned(mission, tmp_path_factory):
    """A small plan (2 pairs), stochastic dithers around each scenario, and its report."""
    out = tmp_path_factory.mktemp("report") / "plan"
    cfg = GenerateConfig(budget=1000, batch_size=250, dithers=60, pairs=2, store=out.parent / "study.db")
    plan = generate(mission, MISSION, out, cfg)
    dithers = {}
    for k, s in enumerate(plan["scenarios"]):
        u = np.array(s["u"])
        rng = np.random.default_rng(k)
        U = np.clip(u + 0.02 * rng.standard_normal((30, u.size)), 0.0, 1.0)
        r = sim.uuv.simulate(mission, U, seed=k, stochastic=True)
        dithers[s["id"]] = (U, np.where(r.valid, r.modes, -1))
    path = write_report(plan, out, dithers)
    return plan, out, path


def _chromium() -> str:
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.fail(
            "headless Chromium is needed to render the report and was not found as `chromium` or "
            "`chromium-browser`; install it, e.g. `sudo apt-get install -y chromium` (Debian/Ubuntu) "
            "or see .ci/run",
            pytrace=False,
        )
    return exe


def _run_chromium(exe: str, profile: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [
        exe,
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--hide-scrollbars",
        "--no-first-run",
        "--disable-extensions",
        f"--user-data-dir={profile}",
        *args,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60)


@pytest.mark.slow  # the module's plan and report, about 40 s together
def test_every_figure_is_a_png_on_disk_and_the_page_is_self_contained(planned):
    plan, out, path = planned
    assert path == out / "report.html"
    page = path.read_text(encoding="utf-8")
    tags = _tags(page)
    # modes, boundary types, sensitivity; per pair a map, parallel coordinates and dithering
    assert len(tags.imgs) == 3 + 3 * len(plan["pairs"]) and len(plan["pairs"]) == 2
    for src in tags.imgs:
        assert src and not src.startswith(("/", "http:", "https:", "file:")), src
        png = out / src
        assert png.is_file() and png.stat().st_size > 0, src
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", src
    assert tags.scripts == 0 and "javascript:" not in page.lower()
    assert not re.search(r"\son[a-z]+\s*=", page)  # no inline event handlers either
    assert "http://" not in page and "https://" not in page
    for title in ("Performance modes and boundary types", "Sensitivity", "Run order"):
        assert title in page
    # every scenario's files are linked, in run order
    hrefs = [h for h in tags.links if h != "plan.json"]
    expected = [
        s["files"][k]
        for sid in plan["run_order"]
        for s in plan["scenarios"]
        if s["id"] == sid
        for k in ("plan", "waypoints", "geojson")
    ]
    assert hrefs == expected and all((out / h).is_file() for h in hrefs)
    for s in plan["scenarios"]:
        assert s["id"] in page and f"{100 * s['dithering']['p_predicted_mode']:.0f}%" in page


@pytest.mark.slow  # the module's plan and report, about 40 s together
def test_report_renders_in_headless_chromium_with_every_figure_loaded(planned, tmp_path):
    _, out, path = planned
    exe = _chromium()
    n_img = len(_tags(path.read_text(encoding="utf-8")).imgs)

    shot = tmp_path / "shot.png"
    r = _run_chromium(
        exe, tmp_path / "profile1", f"--screenshot={shot}", "--window-size=1280,4000", path.resolve().as_uri()
    )
    assert shot.is_file(), f"chromium wrote no screenshot (exit {r.returncode}): {r.stderr[-2000:]}"
    img = mpimg.imread(shot)
    assert img.shape[:2] == (4000, 1280)
    rgb = img[..., :3].astype(float)
    if rgb.max() > 1.0:
        rgb = rgb / 255.0
    non_white = float(np.mean(rgb.min(axis=2) < 0.92))
    assert non_white > 0.05, f"the rendered page is nearly blank ({non_white:.1%} non-white pixels)"

    # a copy of the page (beside the original, so relative links resolve) with a probe script:
    # once everything has loaded, it counts the images that decoded
    probe = out / "_probe_report.html"
    script = (
        "<script>window.addEventListener('load', function () {"
        "var imgs = Array.prototype.slice.call(document.images);"
        "document.body.dataset.loaded = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;"
        "document.body.dataset.total = imgs.length; });</script>"
    )
    probe.write_text(path.read_text(encoding="utf-8").replace("</body>", script + "</body>"), encoding="utf-8")
    try:
        r = _run_chromium(
            exe, tmp_path / "profile2", "--virtual-time-budget=5000", "--dump-dom", probe.resolve().as_uri()
        )
    finally:
        probe.unlink()
    m = re.search(r'<body[^>]*\bdata-loaded="(\d+)"', r.stdout)
    assert m, f"the probe did not run (exit {r.returncode}): {r.stdout[:300]!r} {r.stderr[-1000:]}"
    total = re.search(r'<body[^>]*\bdata-total="(\d+)"', r.stdout)
    assert int(total.group(1)) == n_img
    assert int(m.group(1)) == n_img, f"only {m.group(1)} of {n_img} figures loaded in Chromium"


@pytest.mark.slow  # the module's plan and report, about 40 s together
def test_text_from_the_plan_is_escaped_and_missing_inputs_degrade(planned, tmp_path):
    plan, out, _ = planned
    bad = copy.deepcopy(plan)
    bad["mission"]["name"] = "<script>alert('x')</script>"
    bad["pairs"] = bad["pairs"][:1]
    bad["pairs"][0]["elements"] = ["<b>waypoints</b>"]
    target = tmp_path / "other"  # no GeoJSON here: the map is replaced by a note
    page = write_report(bad, target).read_text(encoding="utf-8")
    assert "<script>" not in page and "&lt;script&gt;alert(&#x27;x&#x27;)&lt;/script&gt;" in page
    assert "<b>waypoints</b>" not in page and "&lt;b&gt;waypoints&lt;/b&gt;" in page
    assert "map not drawn" in page and "(missing)" in page
    srcs = _tags(page).imgs
    assert len(srcs) == 3 + 1 and all((target / s).is_file() for s in srcs)  # no map, no dithers


@pytest.mark.slow  # the module's plan and report, about 40 s together
def test_wrong_schema_and_bad_dithers_are_one_line_errors(planned, tmp_path):
    plan, _, _ = planned
    with pytest.raises(ValueError, match=r"^plan: expected schema 'rapt.plan/1', got 'rapt.plan/0'$"):
        write_report({**plan, "schema": "rapt.plan/0"}, tmp_path)
    with pytest.raises(ValueError, match=r"^plan: "):
        write_report([], tmp_path)
    sid = plan["scenarios"][0]["id"]
    with pytest.raises(ValueError, match=r"^dithers\["):
        write_report(plan, tmp_path, {sid: (np.zeros((3, 2)), np.zeros(3))})
    assert not (tmp_path / "report.html").exists()


def test_a_permutation_spans_one_labelled_coordinate_per_item():
    # items declared (A, B, C) with keys 0.9, 0.2, 0.5: the order is B, C, A
    plan = {
        "mission": {"dim": 4, "parameters": ["speed", "priority"]},
        "scenarios": [{"u": [0.3, 0.9, 0.2, 0.5], "parameters": {"speed": 1.2, "priority": ["B", "C", "A"]}}],
    }
    labels, owners = _coordinates(plan)
    assert labels == ["speed", "priority[A]", "priority[B]", "priority[C]"]
    assert owners == ["speed", "priority", "priority", "priority"]
