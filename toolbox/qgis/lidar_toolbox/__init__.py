"""QGIS plugin of the lidar toolbox: a Processing provider (pure PyQGIS; the toolbox itself runs
as the command line recorded by ``toolbox qgis install``)."""


def classFactory(iface):  # noqa: N802 - QGIS's name
    from .plugin import LidarToolboxPlugin

    return LidarToolboxPlugin(iface)
