"""semcodec's own JSCC: the network, rate by truncation, the analog refinement layer, on-demand
focus, its link, and the Deep JSCC anchor."""
