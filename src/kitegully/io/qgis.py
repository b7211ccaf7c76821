"""A QGIS project file (``.qgs``) of a site's products, written as plain XML.

No QGIS is needed to write it: the file follows QGIS 3's project format (``<qgis>`` with a
layer tree, ``<projectlayers>`` of ``<maplayer>`` elements with their renderers and the
site CRS). Layer paths are relative to the project (``./dense/dsm.tif``), so the results
folder can be moved or shared as a whole. Styles follow the project's figures: a terrain
colour ramp for the DSM, QGIS's hillshade renderer on the same DSM, the orthophoto in true
colour (its mask band makes unseen cells transparent), gullies in blue, bare soil in red
and checkpoint errors on a diverging scale centred on 0 (blue: DSM below the checkpoint,
red: above).
"""

from __future__ import annotations

import os
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import matplotlib
import numpy as np
import pandas as pd
import pyogrio
import rasterio
from pyproj import CRS

from kitegully import InputError

#: QGIS version the file declares (any QGIS 3 reads it)
QGIS_VERSION = "3.34.0-Prizren"


@dataclass(frozen=True)
class Layer:
    """One layer of the project.

    Attributes
    ----------
    key : str
        Identifier (unique in the project).
    name : str
        Name shown in the layer panel.
    path : Path
        File the layer reads.
    kind : str
        ``raster`` or ``vector``.
    element : ET.Element
        The ``<maplayer>`` element (renderer included).
    visible : bool
        Ticked in the layer panel when the project opens.
    """

    key: str
    name: str
    path: Path
    kind: str
    element: ET.Element = field(repr=False)
    visible: bool = True


def _hex(rgba) -> str:
    r, g, b = (int(round(255 * c)) for c in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def _rgba_str(rgba, alpha: int = 255) -> str:
    r, g, b = (int(round(255 * c)) for c in rgba[:3])
    return f"{r},{g},{b},{alpha}"


def _sub(parent: ET.Element, tag: str, text: str | None = None, **attrib) -> ET.Element:
    el = ET.SubElement(parent, tag, {k: str(v) for k, v in attrib.items()})
    if text is not None:
        el.text = str(text)
    return el


def _spatialrefsys(parent: ET.Element, crs: str) -> ET.Element:
    c = CRS.from_user_input(crs)
    srs = _sub(parent, "spatialrefsys", nativeFormat="Wkt")
    _sub(srs, "wkt", c.to_wkt())
    with warnings.catch_warnings():  # PROJ strings lose datum details; QGIS reads the WKT first
        warnings.simplefilter("ignore", UserWarning)
        _sub(srs, "proj4", c.to_proj4() or "")
    _sub(srs, "srsid", "0")
    auth = c.to_authority()
    _sub(srs, "srid", auth[1] if auth else "0")
    _sub(srs, "authid", f"{auth[0]}:{auth[1]}" if auth else "")
    _sub(srs, "description", c.name)
    _sub(srs, "projectionacronym", "utm" if "UTM" in c.name else "")
    _sub(srs, "ellipsoidacronym", "EPSG:7030" if c.ellipsoid and c.ellipsoid.name == "WGS 84" else "")
    _sub(srs, "geographicflag", "true" if c.is_geographic else "false")
    return srs


def _maplayer(key: str, name: str, source: str, kind: str, provider: str, crs: str,
              extent: Sequence[float], geometry: str | None = None) -> ET.Element:
    attrs = dict(type=kind, hasScaleBasedVisibilityFlag="0", autoRefreshEnabled="0", refreshOnNotifyEnabled="0")
    if geometry:
        attrs.update(geometry=geometry, wkbType={"Point": "Point", "Line": "LineString", "Polygon": "Polygon"}[geometry])
    ml = ET.Element("maplayer", attrs)
    ext = _sub(ml, "extent")
    for tag, v in zip(("xmin", "ymin", "xmax", "ymax"), extent):
        _sub(ext, tag, repr(float(v)))
    _sub(ml, "id", key)
    _sub(ml, "datasource", source)
    _sub(ml, "layername", name)
    _spatialrefsys(_sub(ml, "srs"), crs)
    _sub(ml, "provider", provider, encoding="UTF-8") if kind == "vector" else _sub(ml, "provider", provider)
    return ml


def _rel(path: Path, project_dir: Path) -> str:
    return "./" + Path(os.path.relpath(Path(path).resolve(), project_dir.resolve())).as_posix()


def _raster_pipe(ml: ET.Element, renderer: ET.Element, blend: int = 0) -> None:
    pipe = _sub(ml, "pipe")
    pipe.append(renderer)
    _sub(pipe, "brightnesscontrast", brightness="0", contrast="0", gamma="1")
    _sub(pipe, "huesaturation", saturation="0", grayscaleMode="0", colorizeOn="0", colorizeRed="255",
         colorizeGreen="128", colorizeBlue="128", colorizeStrength="100", invertColors="0")
    _sub(pipe, "rasterresampler", maxOversampling="2", zoomedOutResampler="bilinear")
    _sub(ml, "blendMode", str(blend))  # 0 normal, 13 multiply (QPainter::CompositionMode)


def _raster_extent(path: Path) -> tuple[list[float], rasterio.DatasetReader]:
    try:
        src = rasterio.open(path)
    except rasterio.errors.RasterioIOError as exc:
        raise InputError(f"{path}: cannot open raster for the QGIS project ({exc})") from None
    return list(src.bounds), src


def dsm_layers(path: Path, project_dir: Path, crs: str, azimuth_deg: float, altitude_deg: float) -> list[Layer]:
    """DSM with a terrain colour ramp (2–98 % of its cells) and a hillshade of it (multiply).

    Parameters
    ----------
    path : Path
        The DSM raster (m).
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.
    azimuth_deg, altitude_deg : float
        Sun azimuth and altitude of the hillshade (degrees).

    Returns
    -------
    list of Layer
        The hillshade, then the DSM.
    """
    extent, src = _raster_extent(path)
    with src:
        step = max(1, int(np.ceil(max(src.width, src.height) / 1000)))
        z = src.read(1, out_shape=(int(np.ceil(src.height / step)), int(np.ceil(src.width / step))), masked=True)
    z = np.asarray(z.filled(np.nan), float)
    lo, hi = np.nanpercentile(z, [2, 98]) if np.isfinite(z).any() else (0.0, 1.0)
    hi = hi if hi > lo else lo + 1.0
    src_path = _rel(path, project_dir)
    ml = _maplayer("dsm", "DSM (elevation, m)", src_path, "raster", "gdal", crs, extent)
    r = ET.Element("rasterrenderer", dict(type="singlebandpseudocolor", band="1", opacity="1", alphaBand="-1",
                                         classificationMin=repr(float(lo)), classificationMax=repr(float(hi)),
                                         nodataColor=""))
    _sub(r, "rasterTransparency")
    mm = _sub(r, "minMaxOrigin")
    for tag, v in (("limits", "None"), ("extent", "WholeRaster"), ("statAccuracy", "Estimated"),
                   ("cumulativeCutLower", "0.02"), ("cumulativeCutUpper", "0.98"), ("stdDevFactor", "2")):
        _sub(mm, tag, v)
    shader = _sub(_sub(r, "rastershader"), "colorrampshader", colorRampType="INTERPOLATED", classificationMode="1",
                  clip="0", minimumValue=repr(float(lo)), maximumValue=repr(float(hi)), labelPrecision="2")
    cmap = matplotlib.colormaps["terrain"]
    for t in np.linspace(0.0, 1.0, 9):
        v = lo + t * (hi - lo)
        # terrain without its sea blues: the ramp from 0.25 (lowland green) to 1 (snow)
        _sub(shader, "item", alpha="255", value=repr(float(v)), label=f"{v:.2f} m", color=_hex(cmap(0.25 + 0.75 * t)))
    _raster_pipe(ml, r)
    dsm = Layer("dsm", "DSM (elevation, m)", path, "raster", ml)
    hs_ml = _maplayer("hillshade", "Hillshade of the DSM", src_path, "raster", "gdal", crs, extent)
    h = ET.Element("rasterrenderer", dict(type="hillshade", band="1", opacity="0.5", alphaBand="-1", zfactor="1",
                                          azimuth=repr(float(azimuth_deg)), angle=repr(float(altitude_deg)),
                                          multidirection="0", nodataColor=""))
    _sub(h, "rasterTransparency")
    _raster_pipe(hs_ml, h, blend=13)
    return [Layer("hillshade", "Hillshade of the DSM", path, "raster", hs_ml), dsm]


def orthophoto_layer(path: Path, project_dir: Path, crs: str, key: str = "orthophoto", name: str = "Orthophoto") -> Layer:
    """True-colour orthophoto (bands 1–3, 0–255); its mask band hides cells no image sees.

    Parameters
    ----------
    path : Path
        The orthophoto raster (at least 3 bands).
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.
    key : str
        Layer identifier.
    name : str
        Name shown in the layer panel.

    Returns
    -------
    Layer
        The orthophoto layer.
    """
    extent, src = _raster_extent(path)
    with src:
        count = src.count
    if count < 3:
        raise InputError(f"{path}: orthophoto needs 3 bands (R, G, B) for the QGIS project, has {count}")
    ml = _maplayer(key, name, _rel(path, project_dir), "raster", "gdal", crs, extent)
    r = ET.Element("rasterrenderer", dict(type="multibandcolor", redBand="1", greenBand="2", blueBand="3",
                                         opacity="1", alphaBand="-1", nodataColor=""))
    _sub(r, "rasterTransparency")
    for colour in ("red", "green", "blue"):
        ce = _sub(r, f"{colour}ContrastEnhancement")
        _sub(ce, "minValue", "0")
        _sub(ce, "maxValue", "255")
        _sub(ce, "algorithm", "StretchToMinimumMaximum")
    _raster_pipe(ml, r)
    return Layer(key, name, path, "raster", ml)


def bare_soil_layer(path: Path, project_dir: Path, crs: str) -> Layer:
    """Bare-soil map (0 grass, 1 bare, 255 no data): bare cells red, grass transparent.

    Parameters
    ----------
    path : Path
        The bare-soil raster.
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.

    Returns
    -------
    Layer
        The bare-soil layer, unticked.
    """
    extent, src = _raster_extent(path)
    src.close()
    ml = _maplayer("bare_soil", "Bare soil (OBIA)", _rel(path, project_dir), "raster", "gdal", crs, extent)
    r = ET.Element("rasterrenderer", dict(type="paletted", band="1", opacity="0.7", alphaBand="-1", nodataColor=""))
    _sub(r, "rasterTransparency")
    pal = _sub(r, "colorPalette")
    _sub(pal, "paletteEntry", value="0", color="#4daf4a", alpha="0", label="grass / vegetated")
    _sub(pal, "paletteEntry", value="1", color="#d7301f", alpha="255", label="bare soil")
    _raster_pipe(ml, r)
    return Layer("bare_soil", "Bare soil (OBIA)", path, "raster", ml, visible=False)


def _symbol(parent: ET.Element, kind: str, name: str, props: Mapping[str, str]) -> ET.Element:
    cls = {"line": "SimpleLine", "fill": "SimpleFill", "marker": "SimpleMarker"}[kind]
    sym = _sub(parent, "symbol", type=kind, name=name, alpha="1", clip_to_extent="1", force_rhr="0")
    lay = _sub(sym, "layer", **{"class": cls, "enabled": "1", "locked": "0", "pass": "0"})
    opt = _sub(lay, "Option", type="Map")
    for k, v in props.items():
        _sub(opt, "Option", name=k, type="QString", value=v)
    return sym


def _vector_layer(path: Path, project_dir: Path, crs: str, key: str, name: str, geometry: str) -> tuple[ET.Element, str]:
    try:
        layers = pyogrio.list_layers(path)
        info = pyogrio.read_info(path, layer=layers[0][0])
    except Exception as exc:  # pyogrio raises DataSourceError and friends
        raise InputError(f"{path}: cannot open vector file for the QGIS project ({exc})") from None
    layer = layers[0][0]
    ext = info.get("total_bounds") or (0.0, 0.0, 0.0, 0.0)
    source = f"{_rel(path, project_dir)}|layername={layer}"
    return _maplayer(key, name, source, "vector", "ogr", crs, ext, geometry), layer


def gully_network_layer(path: Path, project_dir: Path, crs: str) -> Layer:
    """Mapped gully network: blue lines.

    Parameters
    ----------
    path : Path
        The gully network vector file (its first layer is shown).
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.

    Returns
    -------
    Layer
        The gully network layer.
    """
    ml, _ = _vector_layer(path, project_dir, crs, "gully_network", "Gully network", "Line")
    rend = _sub(ml, "renderer-v2", type="singleSymbol", symbollevels="0", enableorderby="0", forceraster="0")
    _symbol(_sub(rend, "symbols"), "line", "0", {"line_color": "8,81,156,255", "line_width": "0.6",
                                                  "line_width_unit": "MM", "line_style": "solid"})
    return Layer("gully_network", "Gully network", path, "vector", ml)


def gully_polygons_layer(path: Path, project_dir: Path, crs: str) -> Layer:
    """Gully polygons: translucent blue fill, dark outline.

    Parameters
    ----------
    path : Path
        The gully polygons vector file (its first layer is shown).
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.

    Returns
    -------
    Layer
        The gully polygons layer.
    """
    ml, _ = _vector_layer(path, project_dir, crs, "gully_polygons", "Gully polygons", "Polygon")
    rend = _sub(ml, "renderer-v2", type="singleSymbol", symbollevels="0", enableorderby="0", forceraster="0")
    _symbol(_sub(rend, "symbols"), "fill", "0", {"color": "107,174,214,90", "style": "solid",
                                                  "outline_color": "8,48,107,255", "outline_width": "0.3",
                                                  "outline_width_unit": "MM", "outline_style": "solid"})
    return Layer("gully_polygons", "Gully polygons", path, "vector", ml)


def checkpoint_errors_layer(path: Path, project_dir: Path, crs: str, limit_m: float) -> Layer:
    """Checkpoint errors (DSM − checkpoint, m) as points on a diverging scale centred on 0.

    Six classes with edges at ±limit/2 and ±limit (the validate figures' colour limit);
    points without a DSM value are grey.

    Parameters
    ----------
    path : Path
        The checkpoint points with an ``error_m`` attribute (its first layer is shown).
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.
    limit_m : float
        Colour limit of the errors (m).

    Returns
    -------
    Layer
        The checkpoint errors layer.
    """
    ml, _ = _vector_layer(path, project_dir, crs, "checkpoint_errors", "Checkpoint errors (DSM − checkpoint, m)", "Point")
    L = float(limit_m)
    edges = [-1e6, -L, -L / 2, 0.0, L / 2, L, 1e6]
    cmap = matplotlib.colormaps["RdBu_r"]
    rend = _sub(ml, "renderer-v2", type="graduatedSymbol", attr="error_m", graduatedMethod="GraduatedColor",
                symbollevels="0", enableorderby="0", forceraster="0")
    ranges = _sub(rend, "ranges")
    symbols = _sub(rend, "symbols")
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        mid = (max(a, -L) + min(b, L)) / 2.0
        label = (f"< {-L:g} m" if a == edges[0] else f"> {L:g} m" if b == edges[-1] else f"{a:g} to {b:g} m")
        _sub(ranges, "range", lower=repr(a), upper=repr(b), symbol=str(i), label=label, render="true")
        _symbol(symbols, "marker", str(i), {"name": "circle", "color": _rgba_str(cmap(0.5 + 0.5 * mid / L)),
                                            "outline_color": "35,35,35,255", "outline_width": "0.2", "size": "2.6",
                                            "size_unit": "MM"})
    _symbol(_sub(rend, "source-symbol"), "marker", "0", {"name": "circle", "color": "150,150,150,255", "size": "2.6"})
    _sub(rend, "mode", name="manual")
    return Layer("checkpoint_errors", "Checkpoint errors (DSM − checkpoint, m)", path, "vector", ml)


@dataclass(frozen=True)
class ProductStyle:
    """How a further product of the site is shown.

    Attributes
    ----------
    name : str
        Layer name.
    style : str
        ``ramp`` (continuous raster on a colour map), ``diverging`` (continuous raster on a
        colour map centred on 0, symmetric limits), ``mask`` (0/1 raster, 1 coloured),
        ``rgb`` (3-band image), ``line``, ``polygon``, ``point`` (vectors),
        ``pointcloud`` (LAS/LAZ, QGIS's PDAL provider).
    colour : str
        Matplotlib colour map (rasters) or ``r,g,b,a`` (vectors, masks).
    """

    name: str
    style: str
    colour: str = "8,81,156,255"


def product_style(key: str) -> ProductStyle:
    """The style of a further product key (see :data:`FURTHER_PRODUCTS`); ``KeyError`` if unknown."""
    if key.startswith("hoefle_polygons_t"):
        return ProductStyle(f"Höfle gully polygons, fill depth > {key.removeprefix('hoefle_polygons_t')} m", "polygon",
                            "240,140,60,90")
    if key.startswith("dod_thresholded_"):
        return ProductStyle(f"DoD above the {key.removeprefix('dod_thresholded_')} threshold (m)", "diverging", "RdBu")
    return FURTHER_PRODUCTS[key]


#: Further products shown (unticked) below the main ones: key -> style. Epoch-2 products
#: carry the suffix ``_epoch2``; per-threshold products are styled by :func:`product_style`.
FURTHER_PRODUCTS: dict[str, ProductStyle] = {
    "dsm_epoch2": ProductStyle("DSM epoch 2 (elevation, m)", "ramp", "terrain"),
    "orthophoto_epoch2": ProductStyle("Orthophoto epoch 2", "rgb"),
    "gully_depth": ProductStyle("Gully depth map (m below the smoothed surface)", "ramp", "Blues"),
    "bare_soil_polygons": ProductStyle("Bare soil polygons (OBIA)", "polygon", "215,48,31,80"),
    "camera_positions": ProductStyle("Camera positions (georeferenced)", "point", "20,20,20,255"),
    "camera_positions_epoch2": ProductStyle("Camera positions epoch 2", "point", "90,90,90,255"),
    "sparse_cloud": ProductStyle("Sparse point cloud (SfM tie points)", "pointcloud"),
    "sparse_cloud_epoch2": ProductStyle("Sparse point cloud epoch 2", "pointcloud"),
    "hoefle_dem": ProductStyle("Höfle DEM (minimum-z, m)", "ramp", "terrain"),
    "tci": ProductStyle("Topographic convergence index ln(a / tan b)", "ramp", "viridis"),
    "fill_depth": ProductStyle("Fill depth of the conditioned DEM (m)", "ramp", "Blues"),
    "breaklines": ProductStyle("Breaklines (upper gully edges)", "line", "120,60,20,255"),
    "thalweg": ProductStyle("Thalweg (TCI skeleton)", "line", "30,120,200,255"),
    "transects": ProductStyle("Transects", "line", "150,150,150,255"),
    "medial_axes": ProductStyle("Gully medial axes", "line", "60,60,160,255"),
    "cross_sections": ProductStyle("Cross-sections (width, depth, area)", "line", "200,30,120,255"),
    "dod": ProductStyle("DEM of difference, epoch 2 - epoch 1 (m)", "diverging", "RdBu"),
    "sigma_dod": ProductStyle("Uncertainty of the DoD, 1 sd (m)", "ramp", "magma_r"),
    "stable_ground": ProductStyle("Stable ground used for co-registration", "mask", "120,120,120,110"),
}


def further_layer(key: str, path: Path, project_dir: Path, crs: str) -> Layer:
    """A layer of a further product, styled as :func:`product_style` says (unticked).

    Parameters
    ----------
    key : str
        Further product key (see :data:`FURTHER_PRODUCTS`), also the layer identifier.
    path : Path
        The product's file.
    project_dir : Path
        Folder of the project; the layer's path is written relative to it.
    crs : str
        Site CRS of the layer.

    Returns
    -------
    Layer
        The product's layer, unticked.
    """
    st = product_style(key)
    if st.style in ("ramp", "diverging"):
        return _ramp_raster_layer(path, project_dir, crs, key, st.name, st.colour, st.style == "diverging")
    if st.style == "mask":
        extent, src = _raster_extent(path)
        src.close()
        ml = _maplayer(key, st.name, _rel(path, project_dir), "raster", "gdal", crs, extent)
        r = ET.Element("rasterrenderer", dict(type="paletted", band="1", opacity="1", alphaBand="-1", nodataColor=""))
        _sub(r, "rasterTransparency")
        pal = _sub(r, "colorPalette")
        rgba = st.colour.split(",")
        _sub(pal, "paletteEntry", value="0", color="#ffffff", alpha="0", label="no")
        _sub(pal, "paletteEntry", value="1", color="#{:02x}{:02x}{:02x}".format(*map(int, rgba[:3])), alpha=rgba[3], label="yes")
        _raster_pipe(ml, r)
        return Layer(key, st.name, path, "raster", ml, visible=False)
    if st.style == "rgb":
        lay = orthophoto_layer(path, project_dir, crs, key=key, name=st.name)
        return Layer(key, st.name, path, "raster", lay.element, visible=False)
    if st.style == "pointcloud":
        ml = _maplayer(key, st.name, _rel(path, project_dir), "point-cloud", "pdal", crs, _cloud_extent(path))
        return Layer(key, st.name, path, "pointcloud", ml, visible=False)
    geometry = {"line": "Line", "polygon": "Polygon", "point": "Point"}[st.style]
    ml, _ = _vector_layer(path, project_dir, crs, key, st.name, geometry)
    rend = _sub(ml, "renderer-v2", type="singleSymbol", symbollevels="0", enableorderby="0", forceraster="0")
    props = {"line": {"line_color": st.colour, "line_width": "0.4", "line_width_unit": "MM", "line_style": "solid"},
             "polygon": {"color": st.colour, "style": "solid", "outline_color": st.colour.rsplit(",", 1)[0] + ",255",
                         "outline_width": "0.3", "outline_width_unit": "MM", "outline_style": "solid"},
             "point": {"name": "circle", "color": st.colour, "size": "1.8", "size_unit": "MM"}}[st.style]
    _symbol(_sub(rend, "symbols"), {"polygon": "fill", "point": "marker"}.get(st.style, "line"), "0", props)
    return Layer(key, st.name, path, "vector", ml, visible=False)


def _cloud_extent(path: Path) -> list[float]:
    import laspy

    try:
        with laspy.open(path) as fh:
            h = fh.header
            return [float(h.mins[0]), float(h.mins[1]), float(h.maxs[0]), float(h.maxs[1])]
    except Exception as exc:  # laspy raises LaspyException and OSError subclasses
        raise InputError(f"{path}: cannot open point cloud for the QGIS project ({exc})") from None


def _ramp_raster_layer(path: Path, project_dir: Path, crs: str, key: str, name: str, cmap_name: str,
                       centred: bool) -> Layer:
    """Single-band raster on a colour map over its 2-98 % range (centred: symmetric about 0)."""
    extent, src = _raster_extent(path)
    with src:
        step = max(1, int(np.ceil(max(src.width, src.height) / 1000)))
        z = src.read(1, out_shape=(int(np.ceil(src.height / step)), int(np.ceil(src.width / step))), masked=True)
    z = np.asarray(z.filled(np.nan), float)
    finite = z[np.isfinite(z)]
    if centred:
        m = float(np.percentile(np.abs(finite), 98)) if finite.size else 1.0
        lo, hi = -(m or 1.0), (m or 1.0)
    else:
        lo, hi = np.percentile(finite, [2, 98]) if finite.size else (0.0, 1.0)
        hi = hi if hi > lo else lo + 1.0
    ml = _maplayer(key, name, _rel(path, project_dir), "raster", "gdal", crs, extent)
    r = ET.Element("rasterrenderer", dict(type="singlebandpseudocolor", band="1", opacity="1", alphaBand="-1",
                                         classificationMin=repr(float(lo)), classificationMax=repr(float(hi)),
                                         nodataColor=""))
    _sub(r, "rasterTransparency")
    shader = _sub(_sub(r, "rastershader"), "colorrampshader", colorRampType="INTERPOLATED", classificationMode="1",
                  clip="0", minimumValue=repr(float(lo)), maximumValue=repr(float(hi)), labelPrecision="2")
    cmap = matplotlib.colormaps[cmap_name]
    for t in np.linspace(0.0, 1.0, 9):
        v = lo + t * (hi - lo)
        # RdBu runs red -> blue; erosion (negative) red, deposition blue as in the change figures
        _sub(shader, "item", alpha="255", value=repr(float(v)), label=f"{v:.2f}", color=_hex(cmap(t)))
    _raster_pipe(ml, r)
    return Layer(key, name, path, "raster", ml, visible=False)


def checkpoint_points(errors_csv: str | Path, crs: str, out_gpkg: str | Path) -> Path:
    """Checkpoint error table (``id, x_m, y_m, z_ref_m, z_model_m, error_m``) as a GeoPackage of points.

    Parameters
    ----------
    errors_csv : str or Path
        The checkpoint error table (CSV); it needs ``x_m``, ``y_m`` and ``error_m``.
    crs : str
        CRS of the table's coordinates.
    out_gpkg : str or Path
        Output GeoPackage (layer ``checkpoint_errors``), overwritten.

    Returns
    -------
    Path
        ``out_gpkg``.
    """
    import geopandas as gpd

    path = Path(errors_csv)
    try:
        df = pd.read_csv(path)
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the checkpoint error table ({exc})") from None
    missing = [c for c in ("x_m", "y_m", "error_m") if c not in df.columns]
    if missing:
        raise InputError(f"{path}: checkpoint error table lacks column(s) {', '.join(missing)}")
    gdf = gpd.GeoDataFrame(df, geometry=gpd.points_from_xy(df["x_m"], df["y_m"]), crs=crs)
    from kitegully.io.vectors import write_vector

    write_vector(gdf, out_gpkg, layer="checkpoint_errors")
    return Path(out_gpkg)


def write_qgis_project(project: str | Path, site: str, crs: str, products: Mapping[str, str | Path],
                       error_limit_m: float = 0.5, azimuth_deg: float = 315.0, altitude_deg: float = 45.0,
                       checkpoint_gpkg: str | Path | None = None) -> list[Layer]:
    """Write ``<site>.qgs`` opening the products a site made, styled; returns its layers.

    Parameters
    ----------
    project
        Output ``.qgs`` file; layer paths are written relative to its folder.
    site, crs
        Site name (project title) and its projected CRS (project and layer CRS).
    products
        Any of ``dsm``, ``orthophoto``, ``gully_network``, ``gully_polygons``, ``bare_soil``,
        ``checkpoint_errors`` (the CSV table), shown ticked; and any further product of
        :func:`product_style` (epoch 2, polygons stage, change stage, cameras, clouds), shown
        unticked below them. Missing keys are layers the site does not make.
    error_limit_m
        Colour limit of the checkpoint errors (``validate.error_limit_m``).
    azimuth_deg, altitude_deg
        Sun of the hillshade (``dense.shading``).
    checkpoint_gpkg
        Where the checkpoint errors are written as points (needed with ``checkpoint_errors``).

    Layers from top to bottom: checkpoint errors, gully network, gully polygons, bare soil,
    hillshade, DSM, orthophoto, then the further products in the order given. Cost: one decimated read of the DSM (≤ 1000² cells).
    """
    project = Path(project)
    pdir = project.parent
    pdir.mkdir(parents=True, exist_ok=True)
    main = {"dsm", "orthophoto", "gully_network", "gully_polygons", "bare_soil", "checkpoint_errors"}
    further = [k for k in products if k not in main]
    unknown = []
    for k in further:
        try:
            product_style(k)
        except KeyError:
            unknown.append(k)
    if unknown:
        raise ValueError(f"unknown product key(s) for the QGIS project: {sorted(unknown)}")
    layers: list[Layer] = []
    if "checkpoint_errors" in products:
        if checkpoint_gpkg is None:
            raise ValueError("checkpoint_errors needs checkpoint_gpkg (where its points are written)")
        gpkg = checkpoint_points(products["checkpoint_errors"], crs, checkpoint_gpkg)
        layers.append(checkpoint_errors_layer(gpkg, pdir, crs, error_limit_m))
    if "gully_network" in products:
        layers.append(gully_network_layer(Path(products["gully_network"]), pdir, crs))
    if "gully_polygons" in products:
        layers.append(gully_polygons_layer(Path(products["gully_polygons"]), pdir, crs))
    if "bare_soil" in products:
        layers.append(bare_soil_layer(Path(products["bare_soil"]), pdir, crs))
    if "dsm" in products:
        layers.extend(dsm_layers(Path(products["dsm"]), pdir, crs, azimuth_deg, altitude_deg))
    if "orthophoto" in products:
        layers.append(orthophoto_layer(Path(products["orthophoto"]), pdir, crs))
    for k in further:
        layers.append(further_layer(k, Path(products[k]), pdir, crs))
    if not layers:
        raise ValueError(f"site {site}: no product to put in the QGIS project")

    root = ET.Element("qgis", projectname=site, version=QGIS_VERSION)
    _sub(root, "homePath", path="")
    _sub(root, "title", site)
    _spatialrefsys(_sub(root, "projectCrs"), crs)
    tree = _sub(root, "layer-tree-group")
    _sub(tree, "customproperties")
    for lay in layers:
        _sub(tree, "layer-tree-layer", id=lay.key, name=lay.name, source=lay.element.findtext("datasource"),
             providerKey=lay.element.findtext("provider"), checked="Qt::Checked" if lay.visible else "Qt::Unchecked",
             expanded="1")
    xs = [[float(lay.element.findtext(f"extent/{t}")) for t in ("xmin", "ymin", "xmax", "ymax")] for lay in layers]
    ext = np.array(xs)
    canvas = _sub(root, "mapcanvas", name="theMapCanvas", annotationsVisible="1")
    _sub(canvas, "units", "meters")
    cext = _sub(canvas, "extent")
    for tag, v in zip(("xmin", "ymin", "xmax", "ymax"), (ext[:, 0].min(), ext[:, 1].min(), ext[:, 2].max(), ext[:, 3].max())):
        _sub(cext, tag, repr(float(v)))
    _sub(canvas, "rotation", "0")
    _spatialrefsys(_sub(canvas, "destinationsrs"), crs)
    order = _sub(root, "layerorder")
    for lay in layers:
        _sub(order, "layer", id=lay.key)
    pl = _sub(root, "projectlayers")
    for lay in layers:
        pl.append(lay.element)
    props = _sub(root, "properties")
    paths = _sub(props, "Paths")
    _sub(paths, "Absolute", "false", type="bool")
    ET.indent(root)
    with open(project, "w", encoding="utf-8") as fh:
        fh.write("<!DOCTYPE qgis PUBLIC 'http://mrcc.com/qgis.dtd' 'SYSTEM'>\n")
        fh.write(ET.tostring(root, encoding="unicode"))
        fh.write("\n")
    return layers


def layer_paths(project: str | Path) -> list[Path]:
    """Files the layers of a ``.qgs`` project read, resolved against its folder."""
    project = Path(project)
    root = ET.parse(project).getroot()
    out = []
    for ds in root.iter("datasource"):
        src = (ds.text or "").split("|")[0]
        p = Path(src)
        out.append((project.parent / p).resolve() if not p.is_absolute() else p)
    return out
