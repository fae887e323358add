#!/usr/bin/env bash
# A minimal OpenFOAM development tree to compile small libraries (boundary conditions, function
# objects) against Debian's INSTALLED OpenFOAM libraries (package `openfoam`/`libopenfoam`, which
# ship no headers and no wmake). Called by scripts/install.sh; as root on Debian bookworm.
#
#   bash scripts/openfoam_dev.sh [setup]            prepare the tree (idempotent; a re-run only checks)
#   bash scripts/openfoam_dev.sh build SRC [OUTDIR] compile the library in SRC (Make/files with
#                                                   LIB = $(FOAM_USER_LIBBIN)/libNAME, Make/options);
#                                                   prints the .so path; rebuilt only when SRC changed
#   bash scripts/openfoam_dev.sh env                print the path of the env file to source
#
# setup: adds a deb-src entry for the release (own file in /etc/apt/sources.list.d/, deb822 or
# one-line format like the machine's), installs dpkg-dev/g++/make if missing, fetches the source
# package of exactly the installed openfoam version (`apt-get source`), unpacks it to
# $VCS_OPENFOAM_DEV/OpenFOAM-<api> (default /opt/vcs-openfoam-dev), builds wmake's helpers
# (lemon, wmkdepend), makes the lnInclude folders of every library under src/, links
# platforms/<WM_OPTIONS>/lib to the installed libraries in /usr/lib, points etc/ at Debian's
# /usr/share/openfoam/etc and writes $VCS_OPENFOAM_DEV/env.sh. OpenFOAM itself is not built.
# The compile options are Debian's: Gcc, DP, Int32 labels, Opt (-O3), -std=c++11, -DNoRepository,
# -ftemplate-depth-100, plus dpkg-buildflags' hardening flags (Debian's 30_hardening.patch).
# A solver loads a built library from controlDict: `libs ("/abs/path/libNAME.so");`, or
# `libs ("libNAME.so");` with its folder in LD_LIBRARY_PATH, or "$FOAM_USER_LIBBIN/libNAME.so".
# codedFixedValue & co. compile at run time: they need env.sh sourced (wmake on PATH,
# WM_PROJECT_DIR = this tree: wmake reads $WM_PROJECT_DIR/src) and refuse to run as root (v1912).
set -euo pipefail

PREFIX=${VCS_OPENFOAM_DEV:-/opt/vcs-openfoam-dev}
PREP_REV=1          # bump when the layout made by setup changes: the next run prepares it again
ENV_FILE=$PREFIX/env.sh

log() { echo "[install] $*" >&"${LOG_FD:-1}"; }  # stdout; stderr for build (its stdout: the .so)
die() { echo "[install] error: $*" >&2; exit 1; }

installed_version() {  # the source version of the installed openfoam (binNMU suffix "+bN" dropped)
  dpkg-query -W -f='${db:Status-Abbrev} ${source:Version}\n' openfoam 2>/dev/null \
    | awk '$1 ~ /^ii/ {print $2}'
}

apt_install() {
  log "apt-get install $*"
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$@" >/dev/null
}

# a deb-src entry for the release, in the format of the machine's own entries
ensure_deb_src() {
  local codename uri f
  codename=$(. /etc/os-release && echo "${VERSION_CODENAME:-bookworm}")
  if grep -rqsE '^[[:space:]]*deb-src[[:space:]]' /etc/apt/sources.list /etc/apt/sources.list.d/*.list \
     || grep -rqsiE '^[[:space:]]*Types:.*deb-src' /etc/apt/sources.list.d/*.sources; then
    return 0
  fi
  if compgen -G '/etc/apt/sources.list.d/*.sources' >/dev/null; then
    # the URI of the first stanza that serves the release itself (not -security/-updates)
    uri=$(awk -v c="$codename" '
      /^[[:space:]]*$/ {u=""; s=0; next}
      tolower($1)=="uris:" {u=$2}
      tolower($1)=="suites:" {for (i=2;i<=NF;i++) if ($i==c) s=1}
      u!="" && s {print u; exit}' /etc/apt/sources.list.d/*.sources)
    f=/etc/apt/sources.list.d/vcs-openfoam-src.sources
    log "adding deb-src ($codename) in $f"
    cat > "$f" <<EOF
# Added by scripts/openfoam_dev.sh (VCS atlas): source packages, for OpenFOAM's headers and wmake
Types: deb-src
URIs: ${uri:-http://deb.debian.org/debian}
Suites: $codename
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
  else
    uri=$(awk -v c="$codename" '$1=="deb" && $0 ~ (" " c " ") {for (i=2;i<=NF;i++) if ($i ~ /:\/\//) {print $i; exit}}' \
      /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null | head -n1)
    f=/etc/apt/sources.list.d/vcs-openfoam-src.list
    log "adding deb-src ($codename) in $f"
    printf '# Added by scripts/openfoam_dev.sh (VCS atlas)\ndeb-src %s %s main\n' \
      "${uri:-http://deb.debian.org/debian}" "$codename" > "$f"
  fi
  apt-get update -qq
}

write_env() {  # $1 = tree
  local tree=$1
  cat > "$ENV_FILE.tmp" <<EOF
# OpenFOAM development environment (written by scripts/openfoam_dev.sh): source it, then
# \`wmake libso <dir>\` compiles against Debian's installed OpenFOAM ($(installed_version)).
# Also good for running the solvers (etc/ is Debian's /usr/share/openfoam/etc) and needed by
# codedFixedValue & co., which call wmake at run time (and refuse to run as root).
export WM_PROJECT=OpenFOAM
export WM_PROJECT_VERSION=$(cat "$tree/.api")
export WM_PROJECT_DIR=$tree
export WM_DIR=\$WM_PROJECT_DIR/wmake
export WM_ARCH=linux64              # as Debian's build (debian/rules) on every architecture
export WM_COMPILER=Gcc
export WM_COMPILER_TYPE=system
export WM_COMPILER_LIB_ARCH=64
export WM_PRECISION_OPTION=DP
export WM_LABEL_SIZE=32
export WM_LABEL_OPTION=Int32
export WM_COMPILE_OPTION=Opt
export WM_OSTYPE=POSIX
export WM_MPLIB=SYSTEMOPENMPI
export WM_OPTIONS=linux64GccDPInt32Opt
export WM_NCOMPPROCS=\${WM_NCOMPPROCS:-$(nproc)}
export FOAM_MPI=openmpi-system
export FOAM_API=\${WM_PROJECT_VERSION#v}
export FOAM_ETC=\$WM_PROJECT_DIR/etc
export FOAM_SRC=\$WM_PROJECT_DIR/src
export FOAM_APP=\$WM_PROJECT_DIR/applications
export FOAM_SOLVERS=\$FOAM_APP/solvers
export FOAM_UTILITIES=\$FOAM_APP/utilities
export FOAM_APPBIN=/usr/bin
export FOAM_LIBBIN=\$WM_PROJECT_DIR/platforms/\$WM_OPTIONS/lib
export FOAM_USER_LIBBIN=\${FOAM_USER_LIBBIN:-$PREFIX/lib}
export FOAM_USER_APPBIN=\${FOAM_USER_APPBIN:-$PREFIX/bin}
case ":\$PATH:" in *":\$WM_DIR:"*) ;; *) export PATH=\$WM_DIR:\$PATH ;; esac
case ":\${LD_LIBRARY_PATH:-}:" in *":\$FOAM_USER_LIBBIN:"*) ;;
  *) export LD_LIBRARY_PATH=\$FOAM_USER_LIBBIN\${LD_LIBRARY_PATH:+:\$LD_LIBRARY_PATH} ;; esac
EOF
  mv "$ENV_FILE.tmp" "$ENV_FILE"
}

setup() {
  local ver stamp tree dsc lib d
  ver=$(installed_version)
  if [ -z "$ver" ]; then
    log "OpenFOAM dev tree skipped: Debian's openfoam package is not installed"
    return 0
  fi
  stamp=$PREFIX/.ready-$ver-rev$PREP_REV
  if [ -f "$stamp" ] && [ -f "$ENV_FILE" ]; then
    tree=$(. "$ENV_FILE" && echo "$WM_PROJECT_DIR")
    if [ -x "$tree/platforms/tools/linux64Gcc/wmkdepend" ] && [ -d "$tree/src/finiteVolume/lnInclude" ]; then
      log "OK: OpenFOAM dev tree $tree (source $ver)"
      return 0
    fi
  fi
  local t0=$SECONDS
  log "preparing the OpenFOAM dev tree for openfoam $ver in $PREFIX"
  local need=()
  command -v dpkg-source >/dev/null 2>&1 || need+=(dpkg-dev)
  command -v g++ >/dev/null 2>&1 || need+=(g++)
  command -v make >/dev/null 2>&1 || need+=(make)
  if [ ${#need[@]} -gt 0 ]; then apt-get update -qq; apt_install "${need[@]}"; fi
  ensure_deb_src
  apt-cache showsrc "openfoam=$ver" 2>/dev/null | grep -q '^Package: openfoam' || apt-get update -qq

  mkdir -p "$PREFIX"
  tmp=$(mktemp -d "$PREFIX/.tmp.XXXXXX")
  trap 'rm -rf "$tmp"' EXIT    # tmp: global, for the trap
  # apt drops to user _apt for downloads: let it write there (else a harmless warning)
  chown _apt "$tmp" 2>/dev/null || true
  log "apt-get source openfoam=$ver"
  (cd "$tmp" && apt-get source -qq --download-only "openfoam=$ver" >/dev/null)
  dsc=$(ls "$tmp"/openfoam_*.dsc)
  # (its gpgv says "Can't check signature: No public key" without debian-keyring: apt has
  # already checked the files against the signed Sources index)
  dpkg-source -q -x "$dsc" "$tmp/tree" > "$tmp/dpkg-source.log" 2>&1 \
    || { cat "$tmp/dpkg-source.log" >&2; die "dpkg-source -x $dsc failed"; }
  (cd "$tmp/tree" && bin/foamEtcFile -show-api) > "$tmp/api" 2>/dev/null || echo 1912 > "$tmp/api"
  tree=$PREFIX/OpenFOAM-v$(cat "$tmp/api")
  echo "v$(cat "$tmp/api")" > "$tmp/tree/.api"
  # not needed to compile (the tutorials are in openfoam-examples): -150 MB
  rm -rf "$tmp/tree/tutorials" "$tmp/tree/doc"
  # etc/: Debian's installed one (same files, configured by Debian), so that this tree also
  # serves as WM_PROJECT_DIR for the solvers; the source's is kept as etc.source
  mv "$tmp/tree/etc" "$tmp/tree/etc.source"
  ln -s /usr/share/openfoam/etc "$tmp/tree/etc"
  # platforms/<WM_OPTIONS>/lib: links to the installed libraries (what wmake passes to -L)
  lib=$tmp/tree/platforms/linux64GccDPInt32Opt/lib
  mkdir -p "$lib"
  dpkg -L libopenfoam | grep -E '^/usr/lib/[^/]+\.so$' | while read -r d; do ln -s "$d" "$lib/"; done
  for d in dummy openmpi-system; do [ -d "/usr/lib/$d" ] && ln -s "/usr/lib/$d" "$lib/$d"; done
  rm -rf "$tree"
  mv "$tmp/tree" "$tree"
  write_env "$tree"
  # shellcheck disable=SC1090
  . "$ENV_FILE"
  log "building wmake's helpers (lemon, wmkdepend)"
  make -s -C "$WM_DIR/src" >/dev/null
  log "lnInclude folders of the libraries under src/"
  find "$FOAM_SRC" -name lnInclude -prune -o -type f -path '*/Make/files' -print | while read -r d; do
    d=${d%/Make/files}
    [ -d "$d/lnInclude" ] || "$WM_DIR/wmakeLnInclude" -s "$d" >/dev/null 2>&1
  done
  rm -f "$PREFIX"/.ready-*
  rm -rf "$tmp"
  touch "$stamp"
  log "OpenFOAM dev tree ready in $((SECONDS - t0)) s: $tree ($(du -sh "$tree" | cut -f1)); env: $ENV_FILE"
}

# compile the library in $1 into $2 (default $FOAM_USER_LIBBIN); prints the .so path
build() {
  local src=${1:?usage: openfoam_dev.sh build SRC [OUTDIR]} out=${2:-} name hash stampf work
  LOG_FD=2
  src=$(cd "$src" && pwd)
  [ -f "$src/Make/files" ] && [ -f "$src/Make/options" ] || die "$src: no Make/files or Make/options"
  [ -f "$ENV_FILE" ] || die "no $ENV_FILE: run bash scripts/openfoam_dev.sh setup first"
  # shellcheck disable=SC1090
  . "$ENV_FILE"
  [ -z "$out" ] || { mkdir -p "$out"; export FOAM_USER_LIBBIN; FOAM_USER_LIBBIN=$(cd "$out" && pwd); }
  mkdir -p "$FOAM_USER_LIBBIN"
  name=$(sed -n 's/^[[:space:]]*LIB[[:space:]]*=[[:space:]]*//p' "$src/Make/files" | tail -n1)
  [ -n "$name" ] || die "$src/Make/files: no LIB = \$(FOAM_USER_LIBBIN)/libNAME line"
  name=$(basename "$name").so
  hash=$( (cd "$src" && find . \( -name lnInclude -o -path "./Make/$WM_OPTIONS" \) -prune -o -type f -print0 \
            | LC_ALL=C sort -z | xargs -0 sha256sum
          echo "$(installed_version) $WM_OPTIONS $(g++ -dumpfullversion)") | sha256sum | cut -c1-16)
  stampf=$FOAM_USER_LIBBIN/.$name.sha256
  if [ -f "$FOAM_USER_LIBBIN/$name" ] && [ "$(cat "$stampf" 2>/dev/null)" = "$hash" ]; then
    log "up to date: $FOAM_USER_LIBBIN/$name"
    echo "$FOAM_USER_LIBBIN/$name"
    return 0
  fi
  # compiled in a copy under $PREFIX/build: the objects never land in the source folder
  work=$PREFIX/build/$(echo "$src" | sha256sum | cut -c1-12)-$(basename "$src")
  mkdir -p "$work"
  rm -rf "$work/src"
  cp -a "$src" "$work/src"
  rm -rf "$work/src/lnInclude" "$work/src/Make/$WM_OPTIONS"
  log "wmake libso $src -> $FOAM_USER_LIBBIN/$name"
  if ! (cd "$work/src" && wmake -s libso) > "$work/wmake.log" 2>&1; then
    cat "$work/wmake.log" >&2
    die "wmake libso $src failed (log above, also in $work/wmake.log)"
  fi
  [ -f "$FOAM_USER_LIBBIN/$name" ] || die "wmake did not write $FOAM_USER_LIBBIN/$name (LIB in Make/files?)"
  echo "$hash" > "$stampf"
  echo "$FOAM_USER_LIBBIN/$name"
}

exec 9>>"${TMPDIR:-/tmp}/vcs-openfoam-dev.lock"
flock 9
case "${1:-setup}" in
  setup) setup ;;
  build) shift; build "$@" ;;
  env) [ -f "$ENV_FILE" ] || die "no $ENV_FILE: run setup first"; echo "$ENV_FILE" ;;
  *) echo "usage: $0 [setup | build SRC [OUTDIR] | env]" >&2; exit 2 ;;
esac
