#!/bin/sh
# Renders README.md's pictures from scenes/pictures/*.rrv into
# scenes/images/*.png (and the float images into build/pictures/), with the
# commands README shows under each picture; `make pictures` runs it. Each
# picture takes a few CPU minutes, so CI does not. Give picture names to
# render only those: sh scenes/tools/pictures.sh fire_classic luneburg
# Run from the repository root; RRV (default ./rrv) is the binary and
# RRV_PICTURE_FLAGS adds options to every render (e.g. --threads 2).
set -e
RRV=${RRV:-./rrv}
mkdir -p build/pictures

# NAME SCENE [extra rrv render options]
pictures='
fire_classic      fire      --integrator classic
fire_refractive   fire
blast_classic     blast     --integrator classic
blast_refractive  blast
heat_shadow       heat_shadow
pyro              pyro
luneburg          luneburg
fisheye           fisheye
'

echo "$pictures" | while read -r name scene extra; do
    [ -n "$name" ] || continue
    if [ $# -gt 0 ]; then
        case " $* " in *" $name "*) ;; *) continue ;; esac
    fi
    # The command as README.md shows it (word-split on purpose).
    echo "$RRV render scenes/pictures/$scene.rrv -o build/pictures/$name.exr --png scenes/images/$name.png $extra"
    # shellcheck disable=SC2086
    "$RRV" render "scenes/pictures/$scene.rrv" -o "build/pictures/$name.exr" \
        --png "scenes/images/$name.png" $extra $RRV_PICTURE_FLAGS
done
