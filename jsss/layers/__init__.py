"""Layered materials: the zero-order Hankel transform (:mod:`.hankel`) and the Kubelka-Munk
combination of slabs in frequency space (:mod:`.kubelka_munk`, Donner & Jensen 2005; d'Eon
et al. 2007 sec. 3-4). The stack's public names are re-exported here."""

from . import hankel, kubelka_munk
from .kubelka_munk import Layer as Layer
from .kubelka_munk import StackResult as StackResult
from .kubelka_munk import combine_spectra as combine_spectra
from .kubelka_munk import layer_boundaries as layer_boundaries
from .kubelka_munk import relative_to as relative_to
from .kubelka_munk import skin_three_layer as skin_three_layer
from .kubelka_munk import stack as stack
from .kubelka_munk import stack_spectra as stack_spectra

__all__ = ["Layer", "StackResult", "combine_spectra", "hankel", "kubelka_munk", "layer_boundaries", "relative_to",
           "skin_three_layer", "stack", "stack_spectra"]
