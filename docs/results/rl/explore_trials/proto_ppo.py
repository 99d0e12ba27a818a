"""Prototype: PPO settings from the environment (NET, ENT, ACT), then the CLI."""

import os
import sys

import torch

import sensorimotor.rl.runner as R
from sensorimotor.cli.app import app

Orig = R.PPO


def PPO(*a, **k):
    pk = {}
    if os.environ.get("NET"):
        n = [int(x) for x in os.environ["NET"].split(",")]
        pk["net_arch"] = dict(pi=n, vf=n)
    if os.environ.get("ACT") == "relu":
        pk["activation_fn"] = torch.nn.ReLU
    if pk:
        k["policy_kwargs"] = pk
    if os.environ.get("ENT"):
        k["ent_coef"] = float(os.environ["ENT"])
    return Orig(*a, **k)


R.PPO = PPO
sys.argv = ["sensorimotor", *sys.argv[1:]]
app()  # the command line, with the patches of this module and of whoever imported it
