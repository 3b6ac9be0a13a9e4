"""The console commands, one module each, and what they share (:mod:`._console`).

=================  ============================================  ============================
command            what it does                                  module
=================  ============================================  ============================
``fit-params``     beam-profile images in, sigma_a/sigma_s'      :mod:`.fit_params`
                   out; ``fit-params batch`` for many
``jsss-render``    TOML scenes to PNG and EXR;                   :mod:`.render`
                   ``jsss-render fit`` a material from a photo
``jsss``           the Jensen 2001 table; ``jsss info``          :mod:`.info`
=================  ============================================  ============================

Each module's ``main(argv=None)`` is its console script and returns the exit status (0; 1 for
a batch with failed rows; 2 for bad input, reported in one line; 130 when interrupted).
Nothing is imported here, so that ``fit-params --help`` and ``--version`` start without JAX
(``jsss-render --help`` lists the methods of :class:`jsss.render.Method`, which loads JAX: about 2 s).
"""
