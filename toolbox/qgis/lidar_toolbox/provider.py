"""Processing provider ``lidartoolbox``: one algorithm per toolbox algorithm, generated from the
descriptions ``toolbox qgis install`` wrote beside this file (``algorithms.json``: what
``toolbox help ALG --json`` says of each) and run through the recorded ``toolbox`` command.

Names: the toolbox id without hyphens; the primary input ``INPUT``, further inputs by their names
in upper case; parameters by their names in upper case; the primary output ``OUTPUT``, the others
``OUTPUT_<NAME>``."""

import json
import os
import queue
import subprocess
import threading
from pathlib import Path

from qgis.core import (QgsProcessingAlgorithm, QgsProcessingException, QgsProcessingParameterBoolean,
                       QgsProcessingParameterEnum, QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterRasterLayer, QgsProcessingParameterString, QgsProcessingProvider)

HERE = Path(__file__).resolve().parent
POINT_FILTER = "LAS/LAZ point clouds (*.las *.laz *.LAS *.LAZ);;ASCII points (*.txt *.xyz *.csv)"
FILTERS = {"raster": "GeoTIFF (*.tif *.tiff)", "vector": "GeoPackage (*.gpkg)", "points": "LAZ (*.laz);;LAS (*.las)",
           "json": "JSON (*.json)", "image": "PNG (*.png)"}


def _settings():
    path = HERE / "toolbox.json"
    if not path.exists():
        raise QgsProcessingException("the lidar toolbox is not configured: run 'toolbox qgis install' in the "
                                     "environment that has the toolbox")
    return json.loads(path.read_text(encoding="utf-8"))


class ToolboxProvider(QgsProcessingProvider):
    def id(self):
        return "lidartoolbox"

    def name(self):
        return "Lidar toolbox"

    def longName(self):  # noqa: N802 - QGIS's names below
        return "Lidar toolbox (laser scanning and photogrammetry)"

    def loadAlgorithms(self):  # noqa: N802
        path = HERE / "algorithms.json"
        if not path.exists():
            return
        for desc in json.loads(path.read_text(encoding="utf-8"))["algorithms"]:
            if _runnable(desc):
                self.addAlgorithm(ToolboxAlgorithm(desc))


def _point_cloud_layers() -> bool:
    """Point cloud inputs as layers where this QGIS can load LAS/LAZ (its PDAL provider; QGIS 3.22
    from Debian has the parameter but not the provider), else as files."""
    import qgis.core
    from qgis.core import QgsProviderRegistry

    return hasattr(qgis.core, "QgsProcessingParameterPointCloudLayer") and \
        "pdal" in QgsProviderRegistry.instance().providerList()


def _runnable(desc) -> bool:
    """Algorithms whose inputs are all files (camera models and folders included)."""
    return bool(desc.get("inputs") or desc.get("outputs"))


def _primary_output(desc):
    outs = [o for o in desc["outputs"] if not o["optional"]]
    return outs[0] if outs else desc["outputs"][0]


class ToolboxAlgorithm(QgsProcessingAlgorithm):
    def __init__(self, desc):
        super().__init__()
        self.desc = desc

    def createInstance(self):  # noqa: N802
        return ToolboxAlgorithm(self.desc)

    def name(self):
        return self.desc["id"].replace("-", "")

    def displayName(self):  # noqa: N802
        return self.desc["title"]

    def group(self):
        return self.desc["plugin"]

    def groupId(self):  # noqa: N802
        return self.desc["plugin"]

    def shortHelpString(self):  # noqa: N802
        lines = [self.desc["description"], "", f"Reference: {self.desc['reference']}" if self.desc["reference"] else ""]
        lines.append("")
        for p in self.desc["parameters"]:
            unit = f" [{p['unit']}]" if p.get("unit") else ""
            rng = ""
            if p.get("minimum") is not None or p.get("maximum") is not None:
                rng = f" ({p.get('minimum')} to {p.get('maximum')})"
            auto = "; empty: auto" if p.get("allow_auto") else ""
            lines.append(f"{p['name'].upper()}{unit}{rng}: {p['description']}{auto}")
        lines.append(f"\n{self.desc['id']} {self.desc['version']} ({self.desc['distribution']})")
        return "\n".join(lines)

    # ---- parameters ---------------------------------------------------------------------------
    def initAlgorithm(self, config=None):  # noqa: N802
        for k, inp in enumerate(self.desc["inputs"]):
            name = "INPUT" if k == 0 else inp["name"].upper()
            label = f"{inp['name']}: {inp['description']}"
            if inp["kind"] == "raster":
                self.addParameter(QgsProcessingParameterRasterLayer(name, label, optional=inp["optional"]))
            elif inp["kind"] == "points" and _point_cloud_layers():
                from qgis.core import QgsProcessingParameterPointCloudLayer  # QGIS 3.18 and later

                self.addParameter(QgsProcessingParameterPointCloudLayer(name, label, optional=inp["optional"]))
            elif inp["kind"] == "points":
                self.addParameter(QgsProcessingParameterFile(name, label, fileFilter=POINT_FILTER,
                                                             optional=inp["optional"]))
            else:  # camera models, folders of photos, vectors: a file or a folder
                behavior = QgsProcessingParameterFile.Folder if inp["kind"] == "folder" else \
                    QgsProcessingParameterFile.File
                self.addParameter(QgsProcessingParameterFile(name, label, behavior=behavior, optional=inp["optional"]))
        for p in self.desc["parameters"]:
            self.addParameter(_parameter(p))
        primary = _primary_output(self.desc)
        for o in self.desc["outputs"]:
            name = "OUTPUT" if o is primary else f"OUTPUT_{o['name'].upper()}"
            label = f"{o['name']}: {o['description']}"
            # not given, a secondary output goes beside the primary one, as on the command line
            optional = o is not primary
            if o["kind"] == "raster":
                param = QgsProcessingParameterRasterDestination(name, label, optional=optional)
            else:
                param = QgsProcessingParameterFileDestination(name, label, FILTERS.get(o["kind"], ""),
                                                              optional=optional)
            if optional:
                param.setCreateByDefault(not o["optional"])
            self.addParameter(param)

    # ---- running ------------------------------------------------------------------------------
    def command(self, parameters, context):
        """The toolbox command line for these parameter values (a list) and the outputs' paths."""
        cmd = [_settings()["toolbox"], "run", self.desc["id"]]
        for k, inp in enumerate(self.desc["inputs"]):
            name = "INPUT" if k == 0 else inp["name"].upper()
            if inp["kind"] == "raster":
                layer = self.parameterAsRasterLayer(parameters, name, context)
                value = layer.source() if layer is not None else ""
            elif inp["kind"] == "points" and _point_cloud_layers():
                layer = self.parameterAsPointCloudLayer(parameters, name, context)
                value = layer.source() if layer is not None else ""
            else:
                value = self.parameterAsFile(parameters, name, context)
            if not value:
                continue
            cmd += [value] if k == 0 else ["--input", f"{inp['name']}={value}"]
        for p in self.desc["parameters"]:
            value = _value(self, p, parameters, context)
            if value is not None:
                cmd += ["--set", f"{p['name']}={value}"]
        primary = _primary_output(self.desc)
        outputs = {}
        for o in self.desc["outputs"]:
            name = "OUTPUT" if o is primary else f"OUTPUT_{o['name'].upper()}"
            path = self.parameterAsOutputLayer(parameters, name, context) if o["kind"] == "raster" else \
                self.parameterAsFileOutput(parameters, name, context)
            if not path:
                continue
            outputs[name] = path
            cmd += ["-o", path] if o is primary else ["--output-path", f"{o['name']}={path}"]
        # QGIS chose (and asked about) the destinations; the toolbox still writes atomically
        return cmd + ["--overwrite", "--json", "--progress-json"], outputs

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        cmd, outputs = self.command(parameters, context)
        feedback.pushCommandInfo(" ".join(cmd))
        report = run_toolbox(cmd, feedback)
        feedback.pushInfo(f"{self.desc['id']}: done in {report.get('timings_s', {}).get('total', '?')} s")
        if context.project() is not None:  # from the GUI: each layer of a GeoPackage, styled from its layer_styles
            kinds = {("OUTPUT" if o is _primary_output(self.desc) else f"OUTPUT_{o['name'].upper()}"): o["kind"]
                     for o in self.desc["outputs"]}
            for name, path in outputs.items():
                if kinds.get(name) == "vector":
                    _load_layers(path, context)
        return outputs


def _load_layers(path, context) -> None:
    from osgeo import ogr
    from qgis.core import QgsProcessingContext

    ds = ogr.Open(path)
    if ds is None:
        return
    for i in range(ds.GetLayerCount()):
        layer = ds.GetLayerByIndex(i).GetName()
        if layer != "layer_styles":
            context.addLayerToLoadOnCompletion(f"{path}|layername={layer}",
                                               QgsProcessingContext.LayerDetails(layer, context.project(), layer))


def _parameter(p):
    name, label = p["name"].upper(), p["description"] + (f" [{p['unit']}]" if p.get("unit") else "")
    optional = p["default"] is None
    if p.get("choices"):
        choices = list(p["choices"])
        return QgsProcessingParameterEnum(name, label, options=choices, optional=optional,
                                          defaultValue=choices.index(p["default"]) if p["default"] in choices else None)
    if p["type"] == "bool":
        return QgsProcessingParameterBoolean(name, label, defaultValue=bool(p["default"]), optional=optional)
    if p["type"] in ("int", "float"):
        kind = QgsProcessingParameterNumber.Integer if p["type"] == "int" else QgsProcessingParameterNumber.Double
        param = QgsProcessingParameterNumber(name, label, type=kind, defaultValue=p["default"], optional=optional)
        if p.get("minimum") is not None:
            param.setMinimum(p["minimum"])
        if p.get("maximum") is not None:
            param.setMaximum(p["maximum"])
        return param
    return QgsProcessingParameterString(name, label, defaultValue=p["default"], optional=optional)


def _value(alg, p, parameters, context):
    """A parameter's value for the command line; None: left to the toolbox (its default, or auto)."""
    name = p["name"].upper()
    if name not in parameters or parameters[name] is None:
        return None
    if p.get("choices"):
        return list(p["choices"])[alg.parameterAsEnum(parameters, name, context)]
    if p["type"] == "bool":
        return "true" if alg.parameterAsBool(parameters, name, context) else "false"
    if p["type"] == "int":
        return str(alg.parameterAsInt(parameters, name, context))
    if p["type"] == "float":
        return repr(alg.parameterAsDouble(parameters, name, context))
    value = alg.parameterAsString(parameters, name, context)
    return value or None


def run_toolbox(cmd, feedback) -> dict:
    """Run the toolbox command; its progress lines drive ``feedback``; Cancel ends it (the
    toolbox then keeps nothing of the run); a failure is a QgsProcessingException with its line."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    for key in ("PYTHONPATH", "PYTHONHOME", "QGIS_PREFIX_PATH"):  # QGIS's Python is not the toolbox's
        env.pop(key, None)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    lines = queue.Queue()
    reader = threading.Thread(target=lambda: [lines.put(x) for x in proc.stderr], daemon=True)
    reader.start()
    errors, main_bar = [], None
    while True:
        try:
            line = lines.get(timeout=0.2)
        except queue.Empty:
            line = None
        if feedback.isCanceled() and proc.poll() is None:
            proc.terminate()
            proc.wait()
            raise QgsProcessingException("cancelled: the toolbox kept nothing of the run")
        if line is None:
            if proc.poll() is not None and not reader.is_alive() and lines.empty():
                break
            continue
        line = line.rstrip("\n")
        try:
            msg = json.loads(line) if line.startswith("{") else None
        except ValueError:
            msg = None
        if isinstance(msg, dict) and "progress" in msg:
            main_bar = main_bar or msg.get("desc")
            if msg.get("desc") == main_bar and msg.get("progress") is not None:
                feedback.setProgress(100.0 * msg["progress"])
            else:
                feedback.setProgressText(f"{msg.get('desc')}: {msg.get('n')}/{msg.get('total') or '?'}")
        elif line:
            errors.append(line)
            feedback.pushInfo(line)
    out = proc.stdout.read()
    if proc.returncode != 0:
        last = next((e for e in reversed(errors) if e.startswith("toolbox:")), errors[-1] if errors else "")
        raise QgsProcessingException(last or f"the toolbox ended with exit code {proc.returncode}")
    try:
        return json.loads(out)
    except ValueError:
        return {}
