"""sphinx-gallery's scraper for the figures spacefit returns (a module of its own: Sphinx pickles the configuration)."""

from __future__ import annotations


class FigureScraper:
    """sphinx-gallery's scraper for the figures spacefit returns: its plot functions make ``matplotlib.figure.Figure``
    objects outside pyplot (no global state), which the matplotlib scraper cannot see; this one saves every Figure
    the example's variables hold, once."""

    def __repr__(self) -> str:  # sphinx-gallery keys its cache by the scrapers' reprs
        return "spacefit.FigureScraper"

    def __call__(self, block, block_vars, gallery_conf) -> str:
        from matplotlib.figure import Figure
        from sphinx_gallery.scrapers import figure_rst

        paths = []
        for value in list(block_vars["example_globals"].values()):
            if isinstance(value, Figure) and not getattr(value, "_shown_in_gallery", False):
                value._shown_in_gallery = True
                path = next(block_vars["image_path_iterator"])
                value.savefig(path, dpi=80)
                paths.append(path)
        return figure_rst(paths, gallery_conf["src_dir"])

