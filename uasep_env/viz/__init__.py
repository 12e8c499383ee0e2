"""Drawing with matplotlib (imported lazily, inside the functions): two engines, one style.

* :mod:`uasep_env.viz.frames` -- live frames of a running world (:class:`Renderer`, the
  environments' ``render()``, :func:`save_frame`);
* :mod:`uasep_env.viz.figures` -- the paper's figure set from recorded episodes
  (:mod:`~uasep_env.viz.trajectory_figure` for figure 7,
  :mod:`~uasep_env.viz.series_figures` for figures 8-14, helpers in
  :mod:`~uasep_env.viz.figure_parts`);
* :mod:`uasep_env.viz.style` -- the colours both use; :mod:`uasep_env.viz.shapes` -- the
  ENU plot coordinates and the reachable ellipsoid's surface and outline.

``uasep_env.rendering`` and ``uasep_env.plotting`` re-export the public names.
"""
