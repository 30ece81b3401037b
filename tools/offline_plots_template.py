"""Build `vendor/dvc_plots_offline.html`: DVC's plots page with Vega, Vega-Lite and vega-embed inlined.

Usage: python tools/offline_plots_template.py
`dvc plots show` writes a page whose scripts load from a CDN (dvc-render's VegaRenderer.SCRIPTS), so the
plots are blank on a machine without internet. `.dvc/config` points `plots.html_template` at the file this
writes: the same three libraries, at the versions dvc-render asks for, from the npm registry (`npm pack`),
inlined; the page keeps DVC's `{plot_divs}` placeholder and drops `{scripts}`. Their BSD-3-Clause licences are
copied beside it.
"""

from __future__ import annotations

import subprocess
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"vega": ("5.20.2", "build/vega.min.js"), "vega-lite": ("5.2.0", "build/vega-lite.min.js"),
            "vega-embed": ("6.18.2", "build/vega-embed.min.js")}  # = dvc_render.vega.VegaRenderer.SCRIPTS
PAGE = """<!DOCTYPE html>
<html>
<head>
    <meta charset="utf-8">
    <title>DVC Plot</title>
{scripts_inline}
    <style>
        table {{
            border-spacing: 15px;
        }}
    </style>
</head>
<body>
    {{plot_divs}}
</body>
</html>
"""


def main() -> None:
    inline, licences = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name, (version, member) in PACKAGES.items():
            tgz = subprocess.run(["npm", "pack", "-q", f"{name}@{version}"], cwd=tmp, check=True,
                                 capture_output=True, text=True).stdout.split()[-1]
            with tarfile.open(Path(tmp) / tgz) as tar:
                js = tar.extractfile(f"package/{member}").read().decode()
                licence = tar.extractfile("package/LICENSE").read().decode()
            if "</script" in js or "{plot_divs}" in js:
                raise RuntimeError(f"{name}@{version} cannot be inlined as it is")
            inline.append(f"    <!-- {name}@{version} (BSD-3-Clause, see dvc_plots_offline.LICENSES) -->\n"
                          f"    <script>{js}</script>")
            licences.append(f"{name}@{version}\n\n{licence.strip()}\n")
    out = ROOT / "vendor"
    out.mkdir(exist_ok=True)
    (out / "dvc_plots_offline.html").write_text(PAGE.format(scripts_inline="\n".join(inline)))
    (out / "dvc_plots_offline.LICENSES").write_text("\n\n".join(licences))
    print(f"wrote {out / 'dvc_plots_offline.html'}")


if __name__ == "__main__":
    main()
