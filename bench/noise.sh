# Sourced by the benchmarks that measure an image's noise against itself (bench/adaptive.sh, bench/cycles_adaptive.sh).
# noise A.exr B.exr: two renders of one image with different seeds, pixel values clamped to [0, 1] (the displayable
# range), RGB only: the RMS of their difference over sqrt(2) (the noise of one image), relative to the image's mean.
noise() {
  local sq mean
  sq=$(oiiotool "$1" --ch R,G,B --clamp:min=0:max=1 "$2" --ch R,G,B --clamp:min=0:max=1 --sub --dup --mul \
    --printstats 2>&1 | sed -n 's/.*Stats Avg: \([-0-9.e]*\) \([-0-9.e]*\) \([-0-9.e]*\).*/\1 \2 \3/p')
  mean=$(oiiotool "$1" --ch R,G,B --clamp:min=0:max=1 --printstats 2>&1 |
    sed -n 's/.*Stats Avg: \([-0-9.e]*\) \([-0-9.e]*\) \([-0-9.e]*\).*/\1 \2 \3/p')
  awk -v sq="$sq" -v mean="$mean" 'BEGIN { split(sq, s); split(mean, m);
    printf "%.6g\n", sqrt((s[1] + s[2] + s[3]) / 3 / 2) / ((m[1] + m[2] + m[3]) / 3) }'
}
