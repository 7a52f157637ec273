#!/usr/bin/env bash
# Close the loop: record the scripted expert on a generated pick benchmark, train a LeRobot ACT
# policy on the recording with lerobot-train, and score it against the random policy on pick_v1
# (Wilson 95 % CIs and molmo-compare's paired test). `make train-demo` runs it; every knob is an
# environment variable (defaults: a modest CPU run).
#
#   WORK=runs/train-demo          everything goes here (benchmark, runs, checkpoint, summary)
#   HOUSES=20 EPISODES_PER_HOUSE=10 SEED=1    the training benchmark (pick_v1 is seed 0)
#   RES=64                        training images are rendered RES x RES (pick_v1's 224 x 224
#                                 frames are resized to it at evaluation: policy.resize=pad)
#   STEPS=20000 BATCH=32 CHUNK=20 ACT training; DEVICE: cuda where torch sees a GPU, else cpu
#   ACT_ARGS="--policy.dim_model=256 ..."     further lerobot-train flags
#   EVAL_LIMIT=60 WORKERS=2       pick_v1 episodes scored per policy, worker processes
set -euo pipefail

PYTHON=${PYTHON:-python}
WORK=${WORK:-runs/train-demo}
HOUSES=${HOUSES:-20}
EPISODES_PER_HOUSE=${EPISODES_PER_HOUSE:-10}
SEED=${SEED:-1}
RES=${RES:-64}
STEPS=${STEPS:-20000}
BATCH=${BATCH:-32}
DEVICE=${DEVICE:-$("$PYTHON" -c 'import torch; print("cuda" if torch.cuda.is_available() else "cpu")')}
read -r -a ACT_ARGS <<< "${ACT_ARGS:-}"
CHUNK=${CHUNK:-20}
EVAL_LIMIT=${EVAL_LIMIT:-60}
WORKERS=${WORKERS:-2}
export HF_HUB_OFFLINE=${HF_HUB_OFFLINE:-1} MUJOCO_GL=${MUJOCO_GL:-egl}

mkdir -p "$WORK"
stamp() { echo "[train-demo $(date -u +%H:%M:%S)] $*"; }

if [ ! -f "$WORK/pick_train/benchmark.json" ]; then
  stamp "1/5 training benchmark: $HOUSES houses x $EPISODES_PER_HOUSE episodes, seed $SEED, ${RES}px cameras"
  "$PYTHON" -m molmo_lerobot.cli.bench generate --task pick --houses "$HOUSES" \
    --episodes-per-house "$EPISODES_PER_HOUSE" --seed "$SEED" --name pick_train --out "$WORK/pick_train.tmp" --force
  "$PYTHON" - "$WORK/pick_train.tmp/benchmark.json" "$RES" <<'EOF'
import json, sys
path, res = sys.argv[1], int(sys.argv[2])
episodes = json.load(open(path))
for ep in episodes:
    ep["img_resolution"] = [res, res]  # smaller frames: a CPU can train on them
json.dump(episodes, open(path, "w"), indent=1)
EOF
  mv "$WORK/pick_train.tmp" "$WORK/pick_train"
fi

if [ ! -f "$WORK/expert/results.json" ]; then
  stamp "2/5 expert recordings (policy=scripted record=true end_on_success=true)"
  "$PYTHON" -m molmo_lerobot.cli.eval policy=scripted benchmark.path="$WORK/pick_train" record=true \
    end_on_success=true workers="$WORKERS" progress=false output_dir="$WORK/expert" \
    || [ -f "$WORK/expert/results.json" ]  # exit 1 only when no episode ran
fi

CKPT="$WORK/train/checkpoints/last/pretrained_model"
if [ ! -f "$CKPT/model.safetensors" ]; then
  stamp "3/5 lerobot-train ACT: $STEPS steps, batch $BATCH, chunk $CHUNK, on $DEVICE"
  rm -rf "$WORK/train"
  "$PYTHON" -m lerobot.scripts.lerobot_train --dataset.repo_id=local/pick_train-scripted \
    --dataset.root="$WORK/expert/dataset" --dataset.video_backend=pyav --policy.type=act \
    --policy.device="$DEVICE" --policy.push_to_hub=false --policy.pretrained_backbone_weights=null \
    --policy.chunk_size="$CHUNK" --policy.n_action_steps="$CHUNK" --policy.use_vae=false \
    --steps="$STEPS" --batch_size="$BATCH" --num_workers=0 --save_freq="$STEPS" --log_freq=100 \
    --wandb.enable=false --output_dir="$WORK/train" "${ACT_ARGS[@]}"
fi

for policy in random trained; do
  out="$WORK/eval-$policy"
  [ -f "$out/results.json" ] && continue
  stamp "4/5 pick_v1 ($EVAL_LIMIT episodes): policy $policy"
  args=(policy=random)
  [ "$policy" = trained ] && args=(policy=lerobot policy.path="$CKPT" policy.device="$DEVICE")
  "$PYTHON" -m molmo_lerobot.cli.eval "${args[@]}" benchmark=pick_v1 limit="$EVAL_LIMIT" workers="$WORKERS" \
    progress=false output_dir="$out" || [ -f "$out/results.json" ]
done

stamp "5/5 trained vs random on pick_v1"
"$PYTHON" -m molmo_lerobot.cli.compare "$WORK/eval-random" "$WORK/eval-trained" | tee "$WORK/compare.txt" || true
"$PYTHON" - "$WORK" <<'EOF' | tee "$WORK/summary.txt"
import json, sys
from pathlib import Path
work = Path(sys.argv[1])
rand, trained = (json.loads((work / f"eval-{p}" / "results.json").read_text()) for p in ("random", "trained"))
expert = json.loads((work / "expert" / "results.json").read_text())
for name, r in (("expert (training data)", expert), ("random", rand), ("trained", trained)):
    ci = "[{:.3f}, {:.3f}]".format(*r["ci95"]) if r["ci95"] else "none (no episode ran)"
    print(f"{name:24s} success {r['n_success']}/{r['n_valid']}  Wilson 95% CI {ci}")
beats = trained["ci95"] is not None and rand["ci95"] is not None and trained["ci95"][0] > rand["ci95"][1]
print(f"trained beats random with non-overlapping CIs: {'yes' if beats else 'no'}")
EOF
