"""Screenshot of the live editor (``csdf edit``) for the README: docs/editor.png.

Starts the editor's server on a copy of a zoo model, opens it in Debian's Chromium
headless (Playwright; WebGL2 on SwiftShader), moves a slider and saves the page.

    .venv/bin/python docs/make_editor_screenshot.py [docs/editor.png] [--model chair]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import threading
import time
from pathlib import Path

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic",
    "--enable-unsafe-swiftshader",
]


def main(argv: list[str] | None = None) -> int:
    """Write the screenshot; returns the exit status."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("output", nargs="?", default="docs/editor.png")
    ap.add_argument("--model", default="chair", help="zoo model to show")
    ap.add_argument("--set", action="append", default=["arm_height=0.22"],
                    help="slider to move, name=value (repeatable)")
    args = ap.parse_args(argv)

    import uvicorn
    from playwright.sync_api import sync_playwright

    from csdf import zoo
    from csdf.editor.server import create_app, free_port

    with tempfile.TemporaryDirectory() as tmp:
        model = Path(tmp) / f"{args.model}.csdf"
        model.write_text(zoo.source(args.model))
        port = free_port()
        server = uvicorn.Server(uvicorn.Config(create_app(model), host="127.0.0.1",
                                               port=port, log_level="warning"))
        thread = threading.Thread(target=server.run, daemon=True)
        thread.start()
        while not server.started:
            time.sleep(0.02)
        try:
            with sync_playwright() as pw:
                browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
                page = browser.new_page(viewport={"width": 1280, "height": 760},
                                        bypass_csp=True)
                page.goto(f"http://127.0.0.1:{port}/")
                page.wait_for_function("window.csdfEditor && window.csdfEditor.ready",
                                       timeout=60_000)
                for item in args.set:
                    name, _, value = item.partition("=")
                    page.locator(f'input[data-name="{name}"]').fill(value)
                page.evaluate("window.csdfEditor.draw()")
                page.screenshot(path=args.output)
                browser.close()
        finally:
            server.should_exit = True
            thread.join(timeout=10)
    print(f"{args.output}: editor screenshot of {args.model}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
