#!/usr/bin/env bash
# The any-arm campaign of docs/reach.md: every arm, every condition, the same seed.
# Usage: bash experiments/reach_campaign.sh OUT_DIR [extra reach_experiment arguments]
# (e.g. --cases 100 --workers 8, or --ray-address auto). One log per arm in OUT_DIR; the
# table rows are the lines that start with '|'. ARMS='ur3 wrist' runs only those arms;
# ARMS='kuka_iiwa baxter_right_arm kinova_j2s6s200' (and the others in 'more') the more arms
# below. MODULE=experiments.redesign_time runs that module on each arm instead (it takes the
# same arm arguments).
set -euo pipefail
out=${1:?usage: reach_campaign.sh OUT_DIR [reach_experiment arguments]}
shift
mkdir -p "$out"
python=${PYTHON:-python}
module=${MODULE:-experiments.reach_experiment}
# What a user of each arm knows: its URDF, and for some the flange to regulate and the task.
arms=(
  'ur3|--example-robot ur3'
  'ur10|--example-robot ur10'
  'panda|--example-robot panda'
  'so100|--example-robot so100 --tip-link gripper'
  'wrist|--urdf urdf/spherical_wrist.urdf --tip-link tool0 --task orientation'
  'ur5|--example-robot ur5'
  'z1|--example-robot z1 --tip-link link06'
  'xarm7|--example-robot xarm7'
  'so101|--example-robot so101 --tip-link gripper_link'
  'talos_left_arm|--example-robot talos_left_arm --tip-link arm_left_7_link'
)
# More arms no one tuned on, run only when ARMS names them (docs/reach.md, "Arms no one tuned
# on"): a URDF's root link and the end of its longest chain, as design_gains takes them.
pybullet_data=$($python -c 'import pybullet_data; print(pybullet_data.getDataPath())' \
  2>/dev/null || echo 'no-pybullet_data')  # reach_experiment then names the missing file
more=(
  "kuka_iiwa|--urdf $pybullet_data/kuka_iiwa/model.urdf --name kuka_iiwa"
  'baxter_right_arm|--example-robot baxter --name baxter_right_arm'
  'kinova_j2s6s200|--example-robot kinova --name kinova_j2s6s200'
  # arms of whole robots, each from the link its arm hangs from (docs/reach.md, "A joint the
  # arm carries")
  'tiago_arm|--example-robot tiago --name tiago_arm --base-link torso_lift_link'
  'tiago_pro_left_arm|--example-robot tiago_pro --name tiago_pro_left_arm
    --base-link torso_lift_link'
  'romeo_left_arm|--example-robot romeo --name romeo_left_arm'
  'g1_left_arm|--example-robot g1 --name g1_left_arm --base-link torso_link'
  'centauro_arm1|--example-robot centauro --name centauro_arm1 --base-link torso_2'
  # two more, each from the link its left arm hangs from, to its hand (docs/reach.md, "A
  # damping that M(q) couples")
  'icub_left_arm|--example-robot icub --name icub_left_arm --base-link chest --tip-link l_hand'
  'alex_left_arm|--example-robot alex --name alex_left_arm --base-link Torso
    --tip-link LeftGripperYawLink'
  # seven more, each from its URDF's root link unless its arm hangs from a body with more
  # limbs, to its flange (docs/reach.md, "Seven more arms no one tuned on")
  'ur5_limited|--example-robot ur5_limited'
  'ur10_limited|--example-robot ur10_limited'
  'b1_z1|--example-robot b1_z1 --tip-link link06'
  'anymal_kinova|--example-robot anymal_kinova'
  'hextilt_arm5|--example-robot hextilt --name hextilt_arm5'
  'talos_right_arm|--example-robot talos_full --name talos_right_arm --base-link torso_2_link
    --tip-link arm_right_7_link'
  'tiago_dual_right_arm|--example-robot tiago_dual --name tiago_dual_right_arm
    --base-link torso_lift_link --tip-link arm_right_7_link'
  # two held out until the stop guard was done, each from the link its left arm hangs from
  # (docs/reach.md, "Two arms held out")
  'human_left_arm|--example-robot human --name human_left_arm --base-link left_clavicle
    --tip-link left_hand'
  'simple_humanoid_left_arm|--example-robot simple_humanoid --name simple_humanoid_left_arm
    --base-link torso --tip-link l_wrist'
  # nine chains no one had run, each from the link it hangs from to its flange (a finger's and
  # a leg's tip for a position task; docs/reach.md, "Nine chains no one had run")
  'g1_right_arm|--example-robot g1_hand --name g1_right_arm --base-link torso_link
    --tip-link right_wrist_yaw_link'
  'romeo_right_arm|--example-robot romeo --name romeo_right_arm --tip-link r_wrist'
  'alex_sake_right_arm|--example-robot alex_sake --name alex_sake_right_arm --base-link Torso
    --tip-link RightGripperYawLink'
  'icub_reduced_right_arm|--example-robot icub_reduced --name icub_reduced_right_arm
    --base-link chest --tip-link r_hand'
  'ur3_limited|--example-robot ur3_limited'
  'ur5_gripper|--example-robot ur5_gripper'
  'panda_collision|--example-robot panda_collision'
  'finger_edu|--example-robot finger_edu --tip-link finger_tip_link --task position'
  'a1_front_left_leg|--example-robot a1 --name a1_front_left_leg --base-link trunk
    --tip-link FL_foot --task position'
)
for entry in "${arms[@]}" "${more[@]}"; do
  name=${entry%%|*}
  if [[ -n "${ARMS:-}" && " $ARMS " != *" $name "* ]]; then
    continue
  fi
  if [[ -z "${ARMS:-}" && " ${more[*]} " == *"$entry"* ]]; then
    continue  # the more arms: only by name
  fi
  # shellcheck disable=SC2086
  $python -m "$module" ${entry#*|} --potential tanh "$@" \
    > "$out/$name.log" 2>&1 || echo "$name: exit $?" >> "$out/failures.txt"
  grep '^| ' "$out/$name.log" | grep -v '^| arm' || true
done
