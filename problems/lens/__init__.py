"""The intra-ocular lens: its shell model, the injector's rigid parts, the fold that
the fold and injection scenes share, frames and animations."""
