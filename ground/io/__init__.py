"""Ground app boundary: orientation/trajectory/event/GCP importers, exporters and the pyproj CRS boundary."""
