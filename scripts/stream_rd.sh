#!/usr/bin/env bash
# Rate-distortion of the tele-presence stream (docs/streaming.md): for every tracked run folder
# given (artex track ... -s pipeline.export_atlases=true), re-encodes its atlases and poses at
# several target rates (and codecs) with `artex stream encode`, plays every stream back with
# `artex stream play --reference RUN --sequence SEQ`, and prints one CSV row per stream.
#   scripts/stream_rd.sh ARTEX OUT_DIR "RATES" "CODECS" NAME=RUN:SEQUENCE ... > rd.csv
set -euo pipefail
artex=$1 out=$2 rates=$3 codecs=$4
shift 4
mkdir -p "$out"
echo "run,codec,target_kbps,pose_kbps,texture_kbps,total_kbps,keyframes,encode_ms,decode_ms,psnr_vs_sender_db,ssim_vs_sender,atlas_psnr_db,receiver_psnr_db,receiver_ssim,sender_psnr_db,sender_ssim,max_hand_error_mm"
for spec in "$@"; do
  name=${spec%%=*} rest=${spec#*=}
  run=${rest%%:*} seq=${rest#*:}
  for codec in $codecs; do
    for rate in $rates; do
      s="$out/${name}_${codec}_${rate}.artx"
      enc=$("$artex" stream encode "$run" -o "$s" -s stream.codec="$codec" -s stream.texture_kbps="$rate")
      "$artex" stream play "$s" -o "$out/${name}_${codec}_${rate}" --reference "$run" --sequence "$seq" > /dev/null
      python3 - "$out/${name}_${codec}_${rate}/report.json" "$name" "$codec" "$rate" "$enc" <<'PY'
import json, re, sys
r = json.load(open(sys.argv[1]))
enc = sys.argv[5]
ms = re.search(r"encoding: ([0-9.]+) ms/frame", enc).group(1)
hand = re.search(r"hands: max ([0-9.]+) mm", enc).group(1)
f = lambda k: "" if r[k] is None else "%.4f" % r[k]
print(",".join([sys.argv[2], sys.argv[3], sys.argv[4], f("pose_kbit_per_s"), f("texture_kbit_per_s"),
                f("total_kbit_per_s"), str(r["keyframes"]), ms, f("decode_ms_per_frame"),
                f("novel_view_psnr_vs_sender_db"), f("novel_view_ssim_vs_sender"),
                f("atlas_psnr_vs_sender_db"), f("receiver_novel_view_psnr_db"),
                f("receiver_novel_view_ssim"), f("sender_novel_view_psnr_db"),
                f("sender_novel_view_ssim"), hand]))
PY
    done
  done
done
