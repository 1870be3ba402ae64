"""Rendering with Mitsuba 3 / Dr.Jit: the only package of spacefit that imports them."""

from spacefit.render.renderer import Renderer as Renderer
from spacefit.render.renderer import render as render
