#!/usr/bin/env bash
# Close the loop: record the scripted expert on a generated pick benchmark, train a LeRobot ACT
# policy on the recording with lerobot-train, and score it against the random policy on pick_v1
# (Wilson 95 % CIs and molmo-compare's paired test). `make train-demo` runs it; every knob is an
# environment variable.
#
#   INPUTS=state                  state: observation.state + observation.environment_state (pick's:
#                                 the object's pose in the robot base frame, its half extents, the
#                                 TCP-to-object vector; privileged ground truth, not a vision policy;
#                                 the cameras are dropped before training);
#                                 images: observation.state + the cameras (needs a GPU's hours)
#   WORK=runs/train-demo-$INPUTS  everything goes here (benchmark, runs, checkpoint, summary)
#   HOUSES EPISODES_PER_HOUSE SEED=1          the training benchmark (pick_v1 is seed 0)
#   RES=64                        training images are rendered RES x RES (pick_v1's 224 x 224
#                                 frames are resized to it at evaluation: policy.resize=pad)
#   STEPS BATCH CHUNK N_ACTION_STEPS          ACT training; DEVICE: cuda where torch sees a GPU, else cpu
#   SAVE_FREQ=$STEPS              checkpoint every SAVE_FREQ steps (checkpoints/last is the newest)
#   NORMALIZATION='{..."ENV":"MEAN_STD"...}'  ACT's normalization_mapping; ACT's own default names no ENV
#                                 and so feeds observation.environment_state in raw metres
#   ACT_ARGS="--policy.dim_model=256 ..."     further lerobot-train flags
#   EVAL_LIMIT=60 WORKERS=2       pick_v1 episodes scored per policy, worker processes
#   HOLD_STEPS=40                 record_hold_steps of the expert recordings: steps kept after its first
#                                 success, so the policy sees the object held (state; images: 10)
#   END_ON_SUCCESS=true           both policies' pick_v1 episodes end at their first success (MolmoSpaces'
#                                 evaluation convention, end_on_success); false: judged at the horizon
#   TRAIN_THREADS=1               torch threads of lerobot-train on cpu (on 2 shared cores, 2 threads
#                                 made a step 20x slower than 1)
# Defaults: state, 30 x 10 episodes, 10000 steps, batch 32, chunk 20 with temporal ensembling (a new
# chunk every step, coefficient 0.01), dim_model 128, 2 encoder layers, lr 2e-4, every input and the
# action mean/std-normalised (a CPU: 9/60 on pick_v1 against random's 0/60, README); images, 20 x 10
# episodes, 20000 steps, batch 32, chunk 20 (a GPU).
set -euo pipefail

PYTHON=${PYTHON:-python}
INPUTS=${INPUTS:-state}
case "$INPUTS" in
  state) defaults=(30 10 10000 32 20 1 "--policy.dim_model=128 --policy.dim_feedforward=512 --policy.n_heads=4
    --policy.n_encoder_layers=2 --policy.optimizer_lr=2e-4 --policy.temporal_ensemble_coeff=0.01") ;;
  images) defaults=(20 10 20000 32 20 20 "") ;;
  *) echo "train_demo.sh: INPUTS=$INPUTS: expected state or images" >&2; exit 2 ;;
esac
WORK=${WORK:-runs/train-demo-$INPUTS}
HOUSES=${HOUSES:-${defaults[0]}}
EPISODES_PER_HOUSE=${EPISODES_PER_HOUSE:-${defaults[1]}}
SEED=${SEED:-1}
RES=${RES:-64}
STEPS=${STEPS:-${defaults[2]}}
BATCH=${BATCH:-${defaults[3]}}
DEVICE=${DEVICE:-$("$PYTHON" -c 'import torch; print("cuda" if torch.cuda.is_available() else "cpu")')}
read -r -a ACT_ARGS <<< "$(echo ${ACT_ARGS-${defaults[6]}})"
CHUNK=${CHUNK:-${defaults[4]}}
N_ACTION_STEPS=${N_ACTION_STEPS:-${defaults[5]}}
EVAL_LIMIT=${EVAL_LIMIT:-60}
HOLD_STEPS=${HOLD_STEPS:-$([ "$INPUTS" = state ] && echo 40 || echo 10)}
END_ON_SUCCESS=${END_ON_SUCCESS:-true}
WORKERS=${WORKERS:-2}
# ACT leaves a feature type its normalization_mapping does not name as it is, and its default names no
# ENV: the object's position would reach the network in raw metres (one centimetre = 0.01)
NORMALIZATION=${NORMALIZATION:-'{"VISUAL":"MEAN_STD","STATE":"MEAN_STD","ENV":"MEAN_STD","ACTION":"MEAN_STD"}'}
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
  stamp "2/5 expert recordings (policy=scripted record=true end_on_success=true, inputs: $INPUTS)"
  "$PYTHON" -m molmo_lerobot.cli.eval policy=scripted benchmark.path="$WORK/pick_train" record=true \
    record_environment_state="$([ "$INPUTS" = state ] && echo true || echo false)" \
    record_hold_steps="$HOLD_STEPS" end_on_success=true workers="$WORKERS" progress=false output_dir="$WORK/expert" \
    || [ -f "$WORK/expert/results.json" ]  # exit 1 only when no episode ran
fi

DATASET="$WORK/expert/dataset"
if [ "$INPUTS" = state ]; then  # no camera among the inputs: drop them, so training decodes no video
  DATASET="$WORK/expert/dataset-state"
  if [ ! -f "$DATASET/meta/info.json" ]; then
    cameras=$("$PYTHON" -c 'import json, sys; f = json.load(open(sys.argv[1]))["features"]
print(repr([k for k in f if k.startswith("observation.images.")]))' "$WORK/expert/dataset/meta/info.json")
    stamp "2/5 lerobot-edit-dataset remove_feature $cameras"
    rm -rf "$DATASET"
    "$PYTHON" -m lerobot.scripts.lerobot_edit_dataset --repo_id=local/pick_train-scripted \
      --root="$WORK/expert/dataset" --new_repo_id=local/pick_train-scripted-state --new_root="$DATASET" \
      --operation.type=remove_feature --operation.feature_names="$cameras"
  fi
fi

CKPT="$WORK/train/checkpoints/last/pretrained_model"
if [ ! -f "$CKPT/model.safetensors" ]; then
  stamp "3/5 lerobot-train ACT ($INPUTS): $STEPS steps, batch $BATCH, chunk $CHUNK ($N_ACTION_STEPS run), on $DEVICE"
  rm -rf "$WORK/train"
  threads=()
  [ "$DEVICE" = cpu ] && threads=(env OMP_NUM_THREADS="${TRAIN_THREADS:-1}")
  "${threads[@]}" "$PYTHON" -m lerobot.scripts.lerobot_train --dataset.repo_id=local/pick_train-scripted \
    --dataset.root="$DATASET" --dataset.video_backend=pyav --policy.type=act \
    --policy.device="$DEVICE" --policy.push_to_hub=false --policy.pretrained_backbone_weights=null \
    --policy.chunk_size="$CHUNK" --policy.n_action_steps="$N_ACTION_STEPS" --policy.use_vae=false \
    --policy.normalization_mapping="$NORMALIZATION" \
    --steps="$STEPS" --batch_size="$BATCH" --num_workers=0 --save_freq="${SAVE_FREQ:-$STEPS}" --log_freq=100 \
    --wandb.enable=false --output_dir="$WORK/train" "${ACT_ARGS[@]}"
fi

for policy in random trained; do
  out="$WORK/eval-$policy"
  [ -f "$out/results.json" ] && continue
  stamp "4/5 pick_v1 ($EVAL_LIMIT episodes): policy $policy"
  args=(policy=random)
  [ "$policy" = trained ] && args=(policy=lerobot policy.path="$CKPT" policy.device="$DEVICE")
  # images: trained on RES x RES frames, so pick_v1's 224 x 224 are letterboxed to that (not lerobot-eval's default)
  [ "$policy" = trained ] && [ "$INPUTS" = images ] && args+=(policy.resize=pad)
  "$PYTHON" -m molmo_lerobot.cli.eval "${args[@]}" benchmark=pick_v1 limit="$EVAL_LIMIT" workers="$WORKERS" \
    end_on_success="$END_ON_SUCCESS" progress=false output_dir="$out" || [ -f "$out/results.json" ]
done

stamp "5/5 trained vs random on pick_v1"
"$PYTHON" -m molmo_lerobot.cli.compare "$WORK/eval-random" "$WORK/eval-trained" | tee "$WORK/compare.txt" || true
"$PYTHON" - "$WORK" "$INPUTS" <<'EOF' | tee "$WORK/summary.txt"
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
print(f"policy inputs: {sys.argv[2]}" + (" (observation.state + observation.environment_state: privileged object pose, "
                                         "no camera)" if sys.argv[2] == "state" else " (observation.state + cameras)"))
EOF
