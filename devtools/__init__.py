"""Developer tools and benchmarks of penny_env: commands run from a clone's root (``python -m devtools.<name>``),
not part of the installed package; they import no study and no agent (docs/architecture.md, "Layers")."""
