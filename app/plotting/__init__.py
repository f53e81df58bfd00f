"""Drawing for the tabs: the braille raster of the live Scope, and plotext plots of runs and
previewed paths (the thesis's ``plotsix.m`` and ``plotdata.m``)."""
