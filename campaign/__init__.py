"""The codec training campaign: training that accumulates across machines and GPU stretches.

The folder holds the campaign (``campaign.json``: its lines of runs and each line's best,
``log.jsonl``: every run's validation against device- and CPU-minutes,
``lines/<line>/best.safetensors``) and the code that continues it
(``python -m campaign continue``), packs what a bare GPU machine needs (``pack``) and
promotes a candidate over the shipped default (``promote``). A repository tool like
``benchmarks``: not part of the installed packages. See docs/training.md.
"""
