"""The condensed inverse behind every contact: the precomputation of K0^-1 over the surface
(`precomputation`), its checked disk cache (`cache`), the factorisation and the condensed solve
(`condensation`, `lapack`), and the cache of K0^-1 columns solved on demand (`columns`)."""
