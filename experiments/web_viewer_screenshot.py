"""The README's picture of the web viewer (``mode=play viewer=web``): the shipped H1 oracle
on a hurdle trail, the camera following a robot that reaches its terminus, half-way
through its episode, as headless Chromium shows the page.

    python experiments/web_viewer_screenshot.py   # -> docs/img/web_viewer_h1_hurdle.png

Needs Debian's chromium (``apt-get install chromium``) and the ``viewer`` extra.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from legoh.config.compose import compose_config
from legoh.viewer import browser
from legoh.viewer.cli import make_viewer

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs/img/web_viewer_h1_hurdle.png")
    parser.add_argument("--trail", default="hurdle")
    parser.add_argument("--share", type=float, default=0.5,
                        help="how far through the followed robot's episode (0-1)")
    args = parser.parse_args()
    if not 0.0 <= args.share <= 1.0:
        raise SystemExit(f"--share={args.share} is out of range: 0 <= share <= 1")
    overrides = [f"trail={args.trail}"]
    viewer = make_viewer(compose_config(*overrides, "web.port=0"), "pretrained", overrides)
    try:
        rollout = viewer.replay.rollout
        robot = next((i for i, o in enumerate(rollout.outcome) if o == "reached"), 0)
        viewer.follow.value = f"robot {robot}"
        viewer.slider.value = int(args.share * rollout.end[robot])
        with browser.open_page(viewer.url) as page:
            for close in page.locator(".mantine-Notification-root button").all():
                close.click()  # the "software WebGL" notice: true here, noise in a picture
            browser.settled_canvas(page)
            args.out.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.out))
        print(f"robot {robot} ({rollout.outcome[robot]}) at step {viewer.slider.value}: "
              f"{args.out}")
    finally:
        viewer.close()


if __name__ == "__main__":
    main()
