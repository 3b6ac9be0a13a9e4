"""The render methods, each an immutable configuration in a file of its own behind :class:`RenderMethod`.

* :class:`Lambert` -- no knobs (the profile's total albedo, no spread);
* :class:`NormalFiltering` -- ``kind`` (spectral or naive filter; Patro 2007);
* :class:`ImageSpace` -- ``samples`` per pixel (Mertens et al. 2003 sec. 5-6);
* :class:`TextureSpace` -- ``size``, ``taps``, ``max_ratio`` (d'Eon et al. 2007 sec. 5).

The planner returns one (``plan.method_config``); :func:`jsss.render.render` prepares and runs
it through :class:`RenderMethod`'s interface (:mod:`.base`).
"""

from .base import PixelShading as PixelShading
from .base import PreparedGeometry as PreparedGeometry
from .base import RenderMethod as RenderMethod
from .base import camera_parts as camera_parts
from .base import camera_radiance as camera_radiance
from .image_space import ImageSpace as ImageSpace
from .lambert import Lambert as Lambert
from .normal_filtering import NormalFiltering as NormalFiltering
from .pixels import PixelMethod as PixelMethod
from .pixels import PixelPrepared as PixelPrepared
from .texture_space import TexturePrepared as TexturePrepared
from .texture_space import TextureSpace as TextureSpace

#: The configuration class of each :class:`~jsss.render.passes.Method`.
CONFIGURATIONS = {config.method: config for config in (Lambert, NormalFiltering, ImageSpace, TextureSpace)}

__all__ = ["CONFIGURATIONS", "ImageSpace", "Lambert", "NormalFiltering", "PixelMethod", "PixelPrepared", "PixelShading",
           "PreparedGeometry", "RenderMethod", "TexturePrepared", "TextureSpace", "camera_parts",
           "camera_radiance"]
