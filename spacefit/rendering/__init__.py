"""Rendering with Mitsuba 3 / Dr.Jit: the only package of spacefit that imports them."""
