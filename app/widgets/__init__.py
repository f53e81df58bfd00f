"""Widgets and drawing shared by the tabs: header and E-stop lamp, scope plot and its braille
raster, limit bar, validated fields, dialogs, run plots."""
