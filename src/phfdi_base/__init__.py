"""phfdi_base: the ground floor every other package of the project stands on.

The block protocol and its registry (:mod:`phfdi_base.blocks`), piecewise
profiles (:mod:`phfdi_base.profiles`), the scenario schema
(:mod:`phfdi_base.spec`), the graph's topic table and time base
(:mod:`phfdi_base.topics`), the YAML reader (:mod:`phfdi_base.yamlfile`) and
the user error (:mod:`phfdi_base.errors`). It imports nothing of the project:
the four cores (ph_plant_sim, valve_actuator, pi_controllers, wavelet_fdi)
stand on it and the application (phfdi) on top of them; see
docs/architecture.md.
"""
