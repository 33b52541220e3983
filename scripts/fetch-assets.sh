#!/usr/bin/env bash
# Fetch freely licensed real assets for `picker synth` into a gitignored folder.
#
#   scripts/fetch-assets.sh [DEST]        (DEST defaults to <repo>/assets)
#
# What it takes, with `apt-get download` + `dpkg -x` (nothing is installed on the system):
#   - blender-data: the CC0 HDR environment maps of Blender's studio lights
#     (usr/share/blender/datafiles/studiolights/world/*.exr, by Greg Zaal / Poly Haven)
#     -> DEST/hdri/blender-data/
#   - sweethome3d: the photographic floor and wall textures of Sweet Home 3D's default
#     texture catalogue (inside sweethome3d.jar; GPL-2+), without its three "Sky" panoramas
#     -> DEST/textures/sweethome3d/{floor,wall}/
#   - gimp-data: GIMP's material patterns (small, 50-156 px, mostly photographic scans) of
#     the folders Wood, Stone, Fabric, Paper and Animal (leather, leopard), as GIMP .pat files
#     that the library decodes itself (GPL-3+ and other free licences, per the package's
#     copyright file) -> DEST/textures/gimp-data/{wood,stone,fabric,paper,animal}/
# Considered and left out: the game texture packages (nexuiz-textures, ufoai-textures,
# openarena-081-textures, colobot-common-textures: 30-450 MB of stylised game art, not
# indoor photographs) and sweethome3d-furniture (120 MB of models, not surface textures).
# Each folder gets the package's Debian copyright file (and upstream licence text where
# there is one); DEST/SOURCES.md lists what came from where under which licence, and
# DEST/README.md describes the layout that `picker_synth::assets::AssetLibrary::scan` reads.
#
# Requirements: apt-get, dpkg, unzip, and Debian package lists that know the two packages.
# If `apt-get download` fails because the lists are missing or stale, the script runs
# `apt-get update` once when it is root; otherwise it tells you to run it (as root).
#
# Idempotent: the folders it manages (hdri/blender-data, textures/sweethome3d,
# textures/gimp-data, SOURCES.md, README.md) are rebuilt in a temporary folder and swapped
# in; anything else under DEST is left alone.
set -euo pipefail

die() {
    echo "fetch-assets: error: $*" >&2
    exit 1
}
info() { echo "fetch-assets: $*" >&2; }

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DEST="${1:-$ROOT/assets}"

for tool in apt-get dpkg dpkg-deb unzip find sort; do
    command -v "$tool" >/dev/null 2>&1 || die "required tool '$tool' not found (this script needs a Debian-like system)"
done

PACKAGES=(blender-data sweethome3d gimp-data)

WORK="$(mktemp -d "${TMPDIR:-/tmp}/fetch-assets.XXXXXX")"
trap 'rm -rf "$WORK"' EXIT
# apt's download sandbox user (_apt) must be able to write here.
chmod 755 "$WORK"
mkdir -p "$WORK/debs" "$WORK/root" "$WORK/out"

download() {
    (cd "$WORK/debs" && apt-get download "${PACKAGES[@]}") >"$WORK/apt.log" 2>&1
}

info "downloading ${PACKAGES[*]} with apt-get download"
if ! download; then
    if [ "$(id -u)" -eq 0 ]; then
        info "apt-get download failed; running apt-get update once and retrying"
        apt-get update >"$WORK/update.log" 2>&1 || {
            cat "$WORK/update.log" >&2
            die "apt-get update failed (network or sources.list?)"
        }
        download || {
            cat "$WORK/apt.log" >&2
            die "apt-get download ${PACKAGES[*]} failed even after apt-get update"
        }
    else
        cat "$WORK/apt.log" >&2
        die "apt-get download ${PACKAGES[*]} failed; run 'sudo apt-get update' and try again"
    fi
fi

declare -A VERSION DEB
for pkg in "${PACKAGES[@]}"; do
    deb="$(find "$WORK/debs" -maxdepth 1 -name "${pkg}_*.deb" | sort | head -n 1)"
    [ -n "$deb" ] || die "apt-get download did not produce a .deb for $pkg"
    DEB[$pkg]="$(basename "$deb")"
    VERSION[$pkg]="$(dpkg-deb -f "$deb" Version)"
    info "unpacking ${DEB[$pkg]}"
    dpkg -x "$deb" "$WORK/root" || die "dpkg -x $deb failed"
done

# ---- HDR environment maps from blender-data ----
world="$WORK/root/usr/share/blender/datafiles/studiolights/world"
[ -d "$world" ] || die "blender-data ${VERSION[blender-data]} has no studiolights/world folder"
hdri="$WORK/out/hdri/blender-data"
mkdir -p "$hdri"
n_hdri=0
while IFS= read -r f; do
    cp "$f" "$hdri/"
    n_hdri=$((n_hdri + 1))
done < <(find "$world" -maxdepth 1 -type f -name '*.exr' | sort)
[ "$n_hdri" -gt 0 ] || die "no .exr files in blender-data's studiolights/world"
[ -f "$world/license.txt" ] && cp "$world/license.txt" "$hdri/LICENSE.txt"
cp "$WORK/root/usr/share/doc/blender-data/copyright" "$hdri/copyright" ||
    die "blender-data has no /usr/share/doc/blender-data/copyright"

# ---- photographic textures from sweethome3d.jar ----
jar="$WORK/root/usr/share/sweethome3d/sweethome3d.jar"
[ -f "$jar" ] || die "sweethome3d ${VERSION[sweethome3d]} has no usr/share/sweethome3d/sweethome3d.jar"
prefix="com/eteks/sweethome3d/io"
unzip -oq "$jar" "$prefix/resources/textures/*" "$prefix/DefaultTexturesCatalog.properties" -d "$WORK/jar" ||
    die "could not unzip the textures out of $jar"
catalog="$WORK/jar/$prefix/DefaultTexturesCatalog.properties"
tex="$WORK/out/textures/sweethome3d"
n_tex=0
# The catalogue pairs `category#N=Floor|Wall|Sky` with `image#N=/com/.../name.jpg`.
while IFS=$'\t' read -r idx category image; do
    case "$category" in
    Floor | Wall) ;;
    *) continue ;; # the "Sky" panoramas are LDR backdrops, not surface materials
    esac
    src="$WORK/jar/${image#/}"
    [ -f "$src" ] || die "catalogue entry $idx names $image, which is not in the jar"
    dir="$tex/$(echo "$category" | tr '[:upper:]' '[:lower:]')"
    mkdir -p "$dir"
    cp "$src" "$dir/"
    n_tex=$((n_tex + 1))
done < <(tr -d '\r' <"$catalog" | awk -F= '
    /^category#[0-9]+=/ { split($1, a, "#"); cat[a[2]] = $2 }
    /^image#[0-9]+=/    { split($1, a, "#"); img[a[2]] = $2 }
    END { for (i in img) if (i in cat) printf "%s\t%s\t%s\n", i, cat[i], img[i] }' | sort -n)
[ "$n_tex" -gt 0 ] || die "no Floor/Wall textures found in sweethome3d's texture catalogue"
cp "$WORK/root/usr/share/doc/sweethome3d/copyright" "$tex/copyright" ||
    die "sweethome3d has no /usr/share/doc/sweethome3d/copyright"

# ---- material patterns from gimp-data ----
patterns="$WORK/root/usr/share/gimp/2.0/patterns"
[ -d "$patterns" ] || die "gimp-data ${VERSION[gimp-data]} has no usr/share/gimp/2.0/patterns folder"
gimp="$WORK/out/textures/gimp-data"
n_pat=0
for folder in Wood Stone Fabric Paper Animal; do
    [ -d "$patterns/$folder" ] || continue
    dir="$gimp/$(echo "$folder" | tr '[:upper:]' '[:lower:]')"
    mkdir -p "$dir"
    while IFS= read -r f; do
        cp "$f" "$dir/"
        n_pat=$((n_pat + 1))
    done < <(find "$patterns/$folder" -maxdepth 1 -type f -name '*.pat' | sort)
done
[ "$n_pat" -gt 0 ] || die "no .pat files in gimp-data's Wood/Stone/Fabric/Paper/Animal patterns"
cp "$WORK/root/usr/share/doc/gimp-data/copyright" "$gimp/copyright" ||
    die "gimp-data has no /usr/share/doc/gimp-data/copyright"

# ---- docs ----
{
    echo "# Sources of the assets in this folder"
    echo
    echo "Generated by \`scripts/fetch-assets.sh\` on $(date -u +%Y-%m-%d) from Debian packages"
    echo "(\`apt-get download\` + \`dpkg -x\`, nothing installed). Do not commit this folder."
    echo
    echo "| folder | files | Debian package | upstream | licence |"
    echo "|---|---|---|---|---|"
    echo "| \`hdri/blender-data/\` | $n_hdri HDR environment maps (OpenEXR, equirectangular) | blender-data ${VERSION[blender-data]} (\`usr/share/blender/datafiles/studiolights/world/\`) | Greg Zaal, HDRI Haven / Poly Haven | CC0 (\`LICENSE.txt\`; package \`copyright\`) |"
    echo "| \`textures/sweethome3d/{floor,wall}/\` | $n_tex photographic textures (JPEG, made to tile) | sweethome3d ${VERSION[sweethome3d]} (\`usr/share/sweethome3d/sweethome3d.jar\`, \`com/eteks/sweethome3d/io/resources/textures/\`) | eTeks (Emmanuel Puybaret), Sweet Home 3D default texture catalogue | GPL-2+ (\`copyright\`) |"
    echo "| \`textures/gimp-data/{wood,stone,fabric,paper,animal}/\` | $n_pat material patterns (GIMP .pat, 50-156 px) | gimp-data ${VERSION[gimp-data]} (\`usr/share/gimp/2.0/patterns/\`) | the GIMP authors | GPL-3+ and other free licences of the package's \`Files: *\` stanza (\`copyright\`) |"
    echo
    echo "## Files"
    echo
    (cd "$WORK/out" && find hdri textures -type f | sort | sed 's/^/- /')
} >"$WORK/out/SOURCES.md"

cat >"$WORK/out/README.md" <<'EOF'
# Real assets for `picker synth` (gitignored)

Made by `scripts/fetch-assets.sh`; see `SOURCES.md` for origins and licences.
Everything works without this folder (procedural textures and skies only).

Layout read by `picker_synth::assets::AssetLibrary::scan`:
- `hdri/**/*.exr|*.hdr` — equirectangular HDR environment maps (linear radiance);
- `textures/**/*.jpg|*.jpeg|*.png|*.pat` — photographs of surfaces (sRGB; `.pat` is a
  GIMP pattern); the parent folder name (`floor`, `wall`, `wood`, ...) is kept as the
  photo's category;
- a file named `copyright`, `LICENSE*` or `COPYING*` in a file's folder (or the nearest
  folder above it inside this one) is that file's licence.

You may add your own files in the same layout (e.g. `textures/mine/floor/*.png` with a
`LICENSE.txt`); re-running the script replaces only `hdri/blender-data/`,
`textures/sweethome3d/`, `textures/gimp-data/`, `SOURCES.md` and this README.
EOF

# ---- swap into place ----
mkdir -p "$DEST/hdri" "$DEST/textures" || die "cannot create $DEST"
rm -rf "$DEST/hdri/blender-data" "$DEST/textures/sweethome3d" "$DEST/textures/gimp-data"
mv "$WORK/out/hdri/blender-data" "$DEST/hdri/blender-data"
mv "$WORK/out/textures/sweethome3d" "$DEST/textures/sweethome3d"
mv "$WORK/out/textures/gimp-data" "$DEST/textures/gimp-data"
mv "$WORK/out/SOURCES.md" "$WORK/out/README.md" "$DEST/"

size="$(du -sh "$DEST" | cut -f1)"
info "done: $n_hdri HDRIs in $DEST/hdri/blender-data, $n_tex textures in $DEST/textures/sweethome3d, $n_pat patterns in $DEST/textures/gimp-data ($size in all)"
