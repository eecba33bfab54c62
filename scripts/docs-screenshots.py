"""Regenerate the explorer's screenshots in docs/ (serve-screenshot.png, serve-linear.png,
serve-cycle.png) from a running `mvem serve`, the way a person sees the page.

Usage (after scripts/test-browser.sh has created .venv-browser and built the CLI):

    .venv-browser/bin/python scripts/docs-screenshots.py [MVEM_BINARY]

MVEM_BINARY defaults to target/release/mvem. Headless Debian Chromium (/usr/bin/chromium) driven
by Playwright, as the browser tests. The page is shown at 1400 x 1000 px; the operating points are
the ones docs/serve.md describes (the paper's first VGT step at 1500 rpm, 110 mg, u_egr 80 %; the
linear model and loop margins at 1500 rpm, 110 mg, u_egr 50 %, u_vgt 60 %; the WHTC in closed
loop with the baseline controllers).
"""

import subprocess
import sys
from pathlib import Path

from playwright.sync_api import sync_playwright

ROOT = Path(__file__).resolve().parent.parent
CLI = sys.argv[1] if len(sys.argv) > 1 else str(ROOT / "target/release/mvem")
DOCS = ROOT / "docs"
FLAGS = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]


def fill_point(page, n_e, u_delta, u_egr, u_vgt):
    for name, v in (("n_e", n_e), ("u_delta", u_delta), ("u_egr", u_egr), ("u_vgt", u_vgt)):
        page.fill(f"input[name={name}]", str(v))
        page.dispatch_event(f"input[name={name}]", "change")


def main():
    server = subprocess.Popen([CLI, "serve", "--port", "0"], stdout=subprocess.PIPE, text=True)
    try:
        line = server.stdout.readline().strip()
        if not line.startswith("listening on "):
            sys.exit(f"docs-screenshots: mvem serve did not start: {line!r}")
        url = line.removeprefix("listening on ")
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=FLAGS)
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(url)
            page.wait_for_selector("body[data-state=ready]", timeout=15000)

            # the step panel: the paper's first VGT step (Fig. 11), the default point
            fill_point(page, 1500, 110, 80, 75)
            page.click("[data-action=step]")
            page.wait_for_selector("#step canvas[data-drawn]", timeout=60000)
            page.wait_for_function("document.querySelector('[data-action=step]').disabled === false")
            page.screenshot(path=str(DOCS / "serve-screenshot.png"))

            # the linear model with its Bode diagram and the loop margins
            fill_point(page, 1500, 110, 50, 60)
            page.click("[data-action=linearize]")
            page.wait_for_selector("canvas[data-plot=bode][data-drawn]", timeout=60000)
            page.click("[data-action=margins]")
            page.wait_for_selector("#margins:not([hidden]) tbody tr", timeout=60000)
            page.wait_for_function("document.querySelector('[data-action=margins]').disabled === false")
            page.locator("#linear").screenshot(path=str(DOCS / "serve-linear.png"))

            # the WHTC in closed loop with its regulation check
            page.select_option("select[name=cycle_mode]", "closed")
            page.click("[data-action=cycle]")
            page.wait_for_selector("canvas[data-plot=cycle][data-drawn]", timeout=180000)
            page.locator("#cycle").screenshot(path=str(DOCS / "serve-cycle.png"))
            browser.close()
    finally:
        server.terminate()
        server.wait(timeout=20)
    for name in ("serve-screenshot.png", "serve-linear.png", "serve-cycle.png"):
        print(f"wrote docs/{name}")


if __name__ == "__main__":
    main()
