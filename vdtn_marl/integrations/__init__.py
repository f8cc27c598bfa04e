"""Adapters that let other libraries' users run vdtn-marl from their own tools.

- :mod:`vdtn_marl.integrations.benchmarl`: BenchMARL tasks of the single-clock faces (needs the
  ``benchmarl`` extra; docs/integrations.md).

Nothing here is imported by the package itself: each adapter imports its library on first use.
"""
