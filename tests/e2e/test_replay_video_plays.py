"""A replay video served on 127.0.0.1 plays in headless Chromium: ready, time advancing, no error."""

import pytest

from metrics.replay.export import ReplaySettings, export_replay
from tests.e2e.browser import chromium, serve_folder
from tests.metrics.test_replay import recorded  # noqa: F401 - the module fixture: recorded sessions

PAGE = """<!doctype html><html><body>
<video id="replay" src="{name}" muted playsinline preload="auto"></video>
<script>
window.errors = [];
document.getElementById('replay').addEventListener('error', () => window.errors.push('error'));
</script>
</body></html>"""


@pytest.mark.slow
@pytest.mark.parametrize("suffix", [".mp4", ".webm"])
def test_replay_video_plays_in_chromium(recorded, tmp_path, suffix):  # noqa: F811
    tissue, trainee, experts = recorded
    export_replay(
        trainee, tissue, tmp_path / f"replay{suffix}", experts, ReplaySettings(fps=30, size=(640, 360))
    )
    (tmp_path / "index.html").write_text(PAGE.format(name=f"replay{suffix}"))
    with serve_folder(tmp_path) as base, chromium() as browser:
        page = browser.new_page()
        page.goto(f"{base}/index.html")
        page.wait_for_function(
            "() => { const v = document.getElementById('replay'); return v.readyState >= 3 || v.error; }",
            timeout=30_000,
        )
        state = page.evaluate(
            "() => { const v = document.getElementById('replay'); return {ready: v.readyState, "
            "error: v.error && v.error.code, width: v.videoWidth, duration: v.duration}; }"
        )
        assert state["error"] is None and state["ready"] >= 3 and state["width"] == 640
        assert state["duration"] > 3.0
        page.evaluate("() => document.getElementById('replay').play()")
        page.wait_for_function("() => document.getElementById('replay').currentTime > 0.5", timeout=30_000)
        first = page.evaluate("() => document.getElementById('replay').currentTime")
        page.wait_for_timeout(400)
        second = page.evaluate("() => document.getElementById('replay').currentTime")
        assert second > first  # still advancing
        assert page.evaluate("() => window.errors") == []
        assert page.evaluate("() => document.getElementById('replay').error") is None
