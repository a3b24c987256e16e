"""The Snakemake workflow's side in the package.

:mod:`.plan`: datasets, targets, inputs and command-line options of the rules;
:mod:`.paths`: every path the workflow writes (the results layout), templates
that the rules and the plan share; :mod:`.variants`: the paper's ablation, the
variants every scene is reconstructed with.
"""
