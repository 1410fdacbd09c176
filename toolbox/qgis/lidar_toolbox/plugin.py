"""The plugin object QGIS loads: it adds the provider to Processing."""

from qgis.core import QgsApplication


class LidarToolboxPlugin:
    def __init__(self, iface):
        self.iface = iface
        self.provider = None

    def initProcessing(self):  # noqa: N802 - QGIS's name
        from .provider import ToolboxProvider

        self.provider = ToolboxProvider()
        QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802
        self.initProcessing()

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
