"""Drawing for the tabs: the braille raster of the live Scope, and figures of runs and
previewed paths (the thesis's ``plotsix.m`` and ``plotdata.m``) drawn in the terminal and
exported as SVG from the same data; a run's response drawn with plotext for ``--plot``
(``app.plotting.terminal``)."""
