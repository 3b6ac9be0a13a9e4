"""The names of the render methods and passes: one enumeration each, the only place they are spelt.

Both are :class:`enum.StrEnum`, so a member equals its name as a string: a scene file, a
command line or a caller may still say ``method = "image-space"``, and ``Method(name)``
turns any spelling a user may type (``normal-filtering`` on a command line) into the member.
"""

from __future__ import annotations

import enum
import re

__all__ = ["Method", "Pass"]


class Method(enum.StrEnum):
    """How the subsurface light of a frame is produced, from cheap to exact."""

    LAMBERT = "lambert"
    NORMAL_FILTERING = "normal filtering"  # Patro 2007
    IMAGE_SPACE = "image-space"  # Mertens et al. 2003
    TEXTURE_SPACE = "texture-space"  # d'Eon et al. 2007 sec. 5

    @classmethod
    def _missing_(cls, value):
        """Other spellings: ``normal-filtering``, ``texture_space``, ``Texture Space``, any case."""
        if isinstance(value, str):
            wanted = re.sub(r"[\s_-]+", "-", value.strip().lower())
            for member in cls:
                if member.value.replace(" ", "-") == wanted:
                    return member
        return None

    @property
    def option(self) -> str:
        """The spelling of ``--method`` (no spaces)."""
        return self.value.replace(" ", "-")


class Pass(enum.StrEnum):
    """The passes of a frame, in the order they run; the planner turns each on or off and says why."""

    TEXTURE_GEOMETRY = "texture geometry"
    IRRADIANCE = "irradiance"
    SHADOWS = "shadows"
    LAYERED_PROFILE = "layered profile"
    SURFACE_MAPS = "surface maps"
    NORMAL_FILTERING = "normal filtering"
    IMAGE_SPACE_INTEGRATION = "image-space integration"
    DIFFUSION = "diffusion"
    STRETCH_CORRECTION = "stretch correction"
    TRANSLUCENT_SHADOW_MAPS = "translucent shadow maps"
    SINGLE_SCATTERING = "single scattering"
    OBLIQUE_INCIDENCE = "oblique incidence"
    EXIT_ANGLE = "exit angle"
    FIRST_LEG = "first leg"
    LAST_LEG = "last leg"
    DEPOSIT_DEPTH = "deposit depth"
    SPECULAR = "specular"
    CAMERA = "camera"
