"""OpenEXR images in and out (see :mod:`jsss.exr`, shared with the renderer's output)."""

from jsss.exr import ExrError, ExrImage, read_exr, write_exr

__all__ = ["ExrError", "ExrImage", "read_exr", "write_exr"]
