"""The offline commands, one module each with ``build_parser()`` and ``main(argv=None) -> int``.

``simulate_bag`` (the plant over a road into a drive bag), ``estimate_bag`` (the estimator over
a drive bag: the bag of estimates and a report), ``estimate_fleet`` (``estimate_bag`` over many
drives on Dask: :mod:`.fleet_drives`, :mod:`.fleet_dask`, :mod:`.fleet_outputs`),
``profile_to_bag`` (a road profile to an LPA bag and back) and ``road_profile_iri`` (IRI per
segment of a profile). :mod:`.cli` holds what they share: the usage-error parser, the
exit-status wrapper and the common options; :mod:`.output_folder` how they write their
outputs (built beside their place and renamed in; ``--force`` replaces only what the command
wrote, never its input). Nothing is imported here: each command loads only what it needs.
"""

__all__ = ['cli', 'output_folder', 'simulate_bag', 'estimate_bag', 'estimate_fleet',
           'fleet_drives', 'fleet_dask', 'fleet_outputs', 'profile_to_bag', 'road_profile_iri']
