"""The explore entropy bonus's confirmation on fresh seeds 5-9 (its threshold in README.md,
written before the data): ``python confirm.py explore/rl.json``."""
import json
import sys

from sensorimotor.rl.results import HEADLINE, fmt_ci, paired_difference

with open(sys.argv[1]) as f:
    rl = json.load(f)
pose = rl["results"]["pose"][HEADLINE]["per_seed"]
rand = rl["results"]["random"][HEADLINE]["per_seed"]
d = paired_difference(pose[5:10], rand[5:10])
print("seeds 5-9 pose", pose[5:10], "random", rand[5:10])
verdict = "confirmed" if d["t_ci_low"] > 0 else "NOT confirmed"
print("pose - random over seeds 5-9:", fmt_ci(d, "+"), verdict)
d10 = paired_difference(pose, rand)
print("pose - random over seeds 0-9:", fmt_ci(d10, "+"))
