"""How the report saves a figure (workbench.report.engine._draw_and_tabulate): laid out once for the PNG and the SVG,
the PNG as matplotlib's own constrained layout draws it, and only dense artists drawn as bitmaps inside the SVG."""

import io
import re
import warnings
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.layout_engine import ConstrainedLayoutEngine
from PIL import Image

from workbench.report.engine import (FIGURE_DPI, SVG_RASTER_MIN_MARKS, SVG_RASTER_MIN_VERTICES, PaperOutcome,
                                     _draw_and_tabulate)
from workbench.specs import FigureSpec

SVG = "{http://www.w3.org/2000/svg}"
SIZE = (3.2, 2.4)  # small figures: the tests stay fast


def _points(n, dims=2, seed=0):
    return np.random.default_rng(seed).normal(size=(n, dims))


def _dense_2d(data, fig):
    ax = fig.add_subplot()
    p = data["p"]
    ax.scatter(p[:, 0], p[:, 1], s=2, c="grey", label="cloud")
    ax.plot([-2, 2], [-2, 2], "r-", label="a sparse line")
    ax.set_xlabel("x label (km)")
    ax.set_ylabel("y label (km)")
    ax.set_title("dense title", fontsize=8)
    ax.legend(fontsize=6)


def _dense_3d(data, fig):
    ax = fig.add_subplot(projection="3d")
    p = data["p"]
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1, c="grey")
    ax.plot([0, 1], [0, 1], [0, 1], "k-")
    ax.set_xlabel("x label (km)")


def _dense_markers(data, fig):
    ax = fig.add_subplot()
    p = data["p"]
    ax.plot(p[:, 0], p[:, 1], "b.", ms=2)  # a Line2D: one SVG mark per point
    ax.set_xlabel("x label (km)")


def _long_line(data, fig):
    ax = fig.add_subplot()
    p = data["p"]
    ax.plot(np.cumsum(p[:, 0]), "k-", lw=0.5)  # no markers: one SVG path, rasterized only past the vertex limit
    ax.set_xlabel("x label (km)")


def _sparse(data, fig):
    """At the threshold, never past it: a scatter of exactly SVG_RASTER_MIN_MARKS points, a marker-less line of
    SVG_RASTER_MIN_VERTICES vertices (one path), a colorbar and a few markers."""
    ax, ax2 = fig.subplots(1, 2)
    p = data["p"]
    ax.scatter(p[:, 0], p[:, 1], s=2, c=p[:, 0])
    t = np.linspace(0, 1, SVG_RASTER_MIN_VERTICES)
    ax2.plot(t, np.sin(40 * t), "k-", lw=0.5)
    ax2.plot(t[::100], np.cos(40 * t[::100]), "r+")
    im = ax2.imshow(np.arange(12.0).reshape(3, 4), extent=(0, 1, -1, 1), aspect="auto", alpha=0.3)
    fig.colorbar(im, ax=ax2)
    ax.set_xlabel("x label (km)")


def _spec(fid, draw, n, dims=2):
    data = {"p": _points(n, dims)}
    return FigureSpec(fid, f"figure {fid}", lambda results, d=data: d, draw, size=SIZE)


def _save(tmp_path, *specs, formats=("png", "svg")):
    outcome = PaperOutcome("t", "test", "quick", (), "", {})
    with warnings.catch_warnings():
        # no "Rasterization of ... will be ignored" may reach the report's stderr (mplot3d's scatter raises it)
        warnings.filterwarnings("error", message="Rasterization")
        _draw_and_tabulate(SimpleNamespace(figures=list(specs), tables=[]), {}, outcome, tmp_path, formats)
    assert not outcome.errors
    return outcome


def _svg(path):
    root = ET.parse(path).getroot()
    return root, [e for e in root.iter(f"{SVG}image")]


def _text_groups(path):
    """The text matplotlib wrote into the SVG, as its comments name it, for the text groups drawn as glyph paths."""
    return set(re.findall(r"<!-- (.*?) -->", path.read_text()))


_MARK = re.compile(r'<use xlink:href="#(?:m[0-9a-f]{10}|C\d+_\d+_[0-9a-f]{10})"')  # a marker or a collection's path


def _vector_marks(path) -> int:
    """The marks (markers, a collection's paths) the SVG draws as vector elements, one ``<use>`` each."""
    return len(_MARK.findall(path.read_text()))


def _glyphs(path) -> int:
    """The glyphs of the SVG's text, drawn as vector paths (``<use>`` of a font's glyph)."""
    return path.read_text().count("<use") - _vector_marks(path)


def _plain_png(spec) -> np.ndarray:
    """The PNG as matplotlib draws it with its own constrained layout at savefig time: an independent reference."""
    fig = Figure(figsize=spec.size, layout="constrained")
    spec.draw(spec.data({}), fig)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=FIGURE_DPI)
    return np.asarray(Image.open(io.BytesIO(buf.getvalue())))


def _plain_svg(spec, folder):
    """The SVG as matplotlib writes it with nothing marked rasterized: the reference for a sparse figure."""
    fig = Figure(figsize=spec.size, layout="constrained")
    spec.draw(spec.data({}), fig)
    fig.savefig(folder / "plain.svg")
    return folder / "plain.svg"


@pytest.mark.parametrize("draw,n,dims", [(_dense_2d, 1500, 2), (_dense_3d, 1500, 3),
                                         (_sparse, SVG_RASTER_MIN_MARKS, 2)])
def test_png_is_what_matplotlibs_own_layout_draws(tmp_path, draw, n, dims):
    spec = _spec("f", draw, n, dims)
    _save(tmp_path, spec)
    ours, plain = np.asarray(Image.open(tmp_path / "f.png")), _plain_png(spec)
    assert ours.shape == plain.shape
    np.testing.assert_array_equal(ours, plain)  # same axes positions, same pixels


def test_layout_runs_once_and_each_file_is_drawn_once(tmp_path, monkeypatch):
    calls, draws, positions = [], [], []
    execute, draw = ConstrainedLayoutEngine.execute, Figure.draw

    def counted(self, fig):
        calls.append(fig)
        return execute(self, fig)

    def drawn(fig, renderer):
        draws.append(type(renderer).__name__)
        return draw(fig, renderer)

    monkeypatch.setattr(ConstrainedLayoutEngine, "execute", counted)
    monkeypatch.setattr(Figure, "draw", drawn)
    savefig = Figure.savefig

    def recorded(fig, *args, **kwargs):
        out = savefig(fig, *args, **kwargs)
        positions.append([tuple(ax.get_position().bounds) for ax in fig.axes])
        return out

    monkeypatch.setattr(Figure, "savefig", recorded)
    _save(tmp_path, _spec("f", _sparse, 50))
    assert len(calls) == 1  # once for both saves
    assert len(draws) == 2  # one draw per file: no layout pass drawing the figure without output first
    assert len(positions) == 2 and len(positions[0]) == 3  # two axes and the colorbar's
    assert positions[1] == positions[0]  # the SVG's axes where the PNG's are


@pytest.mark.parametrize("draw,n,dims", [(_dense_2d, SVG_RASTER_MIN_MARKS + 1, 2),
                                         (_dense_3d, SVG_RASTER_MIN_MARKS + 500, 3),
                                         (_dense_markers, SVG_RASTER_MIN_MARKS + 500, 2),
                                         (_long_line, SVG_RASTER_MIN_VERTICES + 1, 2)])
def test_dense_artist_is_an_image_in_the_svg_and_the_labels_stay_vector(tmp_path, draw, n, dims):
    _save(tmp_path, _spec("f", draw, n, dims))
    _, images = _svg(tmp_path / "f.svg")
    assert len(images) == 1  # the dense artist, alone
    href = images[0].get("{http://www.w3.org/1999/xlink}href") or images[0].get("href")
    assert href.startswith("data:image/png;base64,")
    assert "x label (km)" in _text_groups(tmp_path / "f.svg")  # the labels are glyph paths, not pixels
    assert _glyphs(tmp_path / "f.svg") > 20
    assert _vector_marks(tmp_path / "f.svg") < 20  # the cloud's points are no longer one SVG element each


def test_sparse_figure_holds_no_image_beyond_its_own(tmp_path):
    _save(tmp_path, _spec("f", _sparse, SVG_RASTER_MIN_MARKS))
    _, images = _svg(tmp_path / "f.svg")
    # the imshow and the colorbar's solids (which matplotlib itself rasterizes): no more images than matplotlib's
    # own SVG of the figure holds
    assert len(images) == len(_svg(_plain_svg(_spec("f", _sparse, SVG_RASTER_MIN_MARKS), tmp_path))[1]) == 2
    assert _vector_marks(tmp_path / "f.svg") >= SVG_RASTER_MIN_MARKS  # the scatter's points: vector, one each
    assert "x label (km)" in _text_groups(tmp_path / "f.svg")
