"""Light transport without the diffusion approximation: the Monte Carlo truth and the profiles
exact to radiative transfer that are read from it.

:mod:`.photon_walk` is the random-walk engine, :mod:`.montecarlo` its public front
(profiles of a medium or a layer stack), :mod:`.tables` the scaled ("white") tables that one
absorption-free walk per (eta, g) yields, and :mod:`.profiles` the profiles, radiance and
total reflectance of any medium read from them; its public names are re-exported here
(``jsss.transport.profile``, ``jsss.transport.radiance``, ...).
"""

from . import montecarlo, photon_walk, profiles, tables
from .profiles import FixedSlice as FixedSlice
from .profiles import check_medium as check_medium
from .profiles import check_supported as check_supported
from .profiles import entry_transmittance as entry_transmittance
from .profiles import fixed_slice as fixed_slice
from .profiles import profile as profile
from .profiles import radiance as radiance
from .profiles import slice_values as slice_values
from .profiles import table_info as table_info
from .profiles import total_reflectance as total_reflectance

__all__ = ["FixedSlice", "check_medium", "check_supported", "entry_transmittance", "fixed_slice", "montecarlo",
           "photon_walk", "profile", "profiles", "radiance", "slice_values", "table_info", "tables",
           "total_reflectance"]
