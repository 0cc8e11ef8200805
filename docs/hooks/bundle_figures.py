"""MkDocs hook: the committed paper bundle's headline figures, served by the site from where they live.

Each ``results/paper/EXPERIMENT/headline.png`` becomes ``results/paper-figures/EXPERIMENT.png`` of the site (the
results pages show them), read at build time — never copied into ``docs/`` by hand, so a regenerated bundle is
what the next build shows. A missing bundle simply adds no figure (the strict build then names the broken image
link of the page that wanted it).
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

BUNDLE = Path(__file__).resolve().parents[2] / "results" / "paper"


def on_files(files, config):  # noqa: ANN001, ANN201 - MkDocs hook signature
    for figure in sorted(BUNDLE.glob("*/headline.png")):
        files.append(File.generated(config, f"results/paper-figures/{figure.parent.name}.png",
                                    abs_src_path=str(figure)))
    return files
