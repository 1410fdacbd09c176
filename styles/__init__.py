"""QGIS 3 styles (.qml) for every output layer and raster kind; installed as ``toolbox_styles``."""
