"""The example site's GIS layers as QGIS draws them: QGIS itself (PyQGIS, Debian's qgis and python3-qgis) opens the
run's gis/ files in place with their CRS and renders the map; matplotlib only frames it (axes in site coordinates,
colour bar).

    /usr/bin/python3 studies/site_qgis_view.py RUN_DIR OUT.png      (Debian's Python, which has PyQGIS)

RUN_DIR is a run of config/site_example/site.opts. No basemap tiles can be fetched here: the background is a plain
ground colour where QGIS would draw a tile layer.
"""

import os
import sys

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

from qgis.core import (QgsApplication, QgsColorRampShader, QgsCoordinateReferenceSystem, QgsFillSymbol,  # noqa: E402
                       QgsLineSymbol, QgsMapRendererParallelJob, QgsMapSettings, QgsMarkerSymbol,
                       QgsPalLayerSettings, QgsRasterBandStats, QgsRasterLayer, QgsRasterShader, QgsRectangle,
                       QgsSingleBandPseudoColorRenderer, QgsTextFormat, QgsVectorLayer, QgsVectorLayerSimpleLabeling)
from qgis.PyQt.QtCore import QSize  # noqa: E402
from qgis.PyQt.QtGui import QColor  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
RAMP = ["#ffffcc", "#fed976", "#fd8d3c", "#e31a1c", "#800026"]


def subsidence_layer(path):
    layer = QgsRasterLayer(path, "subsidence (m)")
    stats = layer.dataProvider().bandStatistics(1, QgsRasterBandStats.All)
    lo, hi = stats.minimumValue, stats.maximumValue
    ramp = QgsColorRampShader(lo, hi)
    ramp.setColorRampType(QgsColorRampShader.Interpolated)
    ramp.setColorRampItemList([QgsColorRampShader.ColorRampItem(lo + (hi - lo) * k / (len(RAMP) - 1), QColor(c))
                               for k, c in enumerate(RAMP)])
    shader = QgsRasterShader()
    shader.setRasterShaderFunction(ramp)
    layer.setRenderer(QgsSingleBandPseudoColorRenderer(layer.dataProvider(), 1, shader))
    layer.renderer().setOpacity(0.85)
    return layer, (lo, hi)


def vector(gpkg, name, symbol, label=None):
    layer = QgsVectorLayer(f"{gpkg}|layername={name}", name, "ogr")
    if not layer.isValid():
        return None
    layer.renderer().setSymbol(symbol)
    if label:
        settings = QgsPalLayerSettings()
        settings.fieldName = label
        fmt = QgsTextFormat()
        fmt.setSize(11)
        settings.setFormat(fmt)
        layer.setLabeling(QgsVectorLayerSimpleLabeling(settings))
        layer.setLabelsEnabled(True)
    return layer


def render(run_dir, out_png):
    app = QgsApplication([], False)
    app.initQgis()
    gis = os.path.join(run_dir, "gis")
    gpkg = os.path.join(gis, "pfault.gpkg")
    sub, limits = subsidence_layer(os.path.join(gis, "subsidence.tif"))
    layers = [vector(gpkg, "stations", QgsMarkerSymbol.createSimple({"name": "triangle", "color": "#2c7bb6",
                                                                      "size": "4", "outline_color": "white"}),
                     label="station"),
              vector(gpkg, "fissure_traces", QgsLineSymbol.createSimple({"color": "#67001f", "width": "1.2"})),
              vector(gpkg, "fault_traces", QgsLineSymbol.createSimple({"color": "black", "width": "0.8"})),
              vector(gpkg, "hazard_zones", QgsFillSymbol.createSimple({"color": "255,0,0,60", "outline_color": "red",
                                                                        "outline_width": "0.6"})),
              sub]
    layers = [lyr for lyr in layers if lyr is not None]
    extent = QgsRectangle(sub.extent())
    extent.grow(250.0)
    ms = QgsMapSettings()
    ms.setLayers(layers)
    ms.setDestinationCrs(QgsCoordinateReferenceSystem("EPSG:32650"))
    ms.setBackgroundColor(QColor("#efe9dc"))
    ms.setExtent(extent)
    ms.setOutputSize(QSize(1500, int(1500 * extent.height() / extent.width())))
    job = QgsMapRendererParallelJob(ms)
    job.start()
    job.waitForFinished()
    tmp = out_png + ".qgis.png"
    job.renderedImage().save(tmp, "png")
    frame(tmp, out_png, ms.visibleExtent(), limits, [lyr.name() for lyr in layers])
    os.remove(tmp)
    app.exitQgis()
    os._exit(0)          # PyQGIS 3.22 may crash tearing its objects down after exitQgis: the files are written


def frame(image, out_png, ext, limits, names):
    """Axes in site coordinates around QGIS's image, the subsidence colour bar and the layers drawn."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    img = plt.imread(image)
    fig, ax = plt.subplots(figsize=(11, 6.8), constrained_layout=True)
    ax.imshow(img, extent=(ext.xMinimum(), ext.xMaximum(), ext.yMinimum(), ext.yMaximum()))
    ax.set_xlabel("easting (m, WGS 84 / UTM zone 50N)")
    ax.set_ylabel("northing (m)")
    ax.ticklabel_format(useOffset=False, style="plain")
    sm = plt.cm.ScalarMappable(norm=Normalize(*limits), cmap=LinearSegmentedColormap.from_list("s", RAMP))
    fig.colorbar(sm, ax=ax, shrink=0.7, label="subsidence after 10 years (m, gis/subsidence.tif)")
    ax.set_title("config/site_example in QGIS 3.22 (rendered by PyQGIS from the files): " + "; ".join(names),
                 fontsize=8.5)
    fig.savefig(out_png, dpi=110)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    render(sys.argv[1], sys.argv[2])
