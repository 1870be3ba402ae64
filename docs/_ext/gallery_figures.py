"""sphinx-gallery's scraper for the gallery's figures (a module of its own: Sphinx pickles the configuration)."""

from __future__ import annotations

# Saved at this resolution, a figure of the gallery's 8 to 9 inches is about 1300 px wide: shown at the
# page's width (about 800 px) its 10 pt text stays sharp, also on a high-density screen.
DPI = 160


def figures_in(namespace: dict) -> list:
    """The matplotlib Figures of the Figures, Axes or arrays of Axes (what spacefit's plot functions
    return) that a script's variables hold, each once."""
    import numpy as np
    from matplotlib.artist import Artist
    from matplotlib.figure import Figure, SubFigure

    found = []
    for value in list(namespace.values()):
        if isinstance(value, (list, tuple, np.ndarray)) and len(value):
            value = np.ravel(np.asarray(value, dtype=object))[0]  # an array of axes: its first one's figure
        figure = value.figure if isinstance(value, Artist) and not isinstance(value, Figure) else value
        while isinstance(figure, SubFigure):  # a panel drawn into a subfigure: the figure that holds it
            figure = figure.figure
        if isinstance(figure, Figure) and all(figure is not f for f in found):
            found.append(figure)
    return found


class FigureScraper:
    """sphinx-gallery's scraper for every figure of a code block, in the order made: pyplot's open figures and
    those spacefit's plot functions make outside pyplot (no global state) and return as axes, which sphinx-gallery's
    matplotlib scraper cannot see. Each is saved once, at :data:`DPI` and trimmed to its drawing; pyplot's are
    closed. It replaces the matplotlib scraper, which saved a pyplot figure a second time."""

    def __repr__(self) -> str:  # sphinx-gallery keys its cache by the scrapers' reprs
        return "spacefit.FigureScraper"

    def __call__(self, block, block_vars, gallery_conf) -> str:
        import matplotlib.pyplot as plt
        from sphinx_gallery.scrapers import figure_rst

        figures = [plt.figure(n) for n in plt.get_fignums()]
        figures += [f for f in figures_in(block_vars["example_globals"]) if all(f is not g for g in figures)]
        paths = []
        for figure in figures:
            if not getattr(figure, "_shown_in_gallery", False):
                figure._shown_in_gallery = True
                path = next(block_vars["image_path_iterator"])
                figure.savefig(path, dpi=DPI, bbox_inches="tight", facecolor="white")
                paths.append(path)
        plt.close("all")
        return figure_rst(paths, gallery_conf["src_dir"])
