#!/usr/bin/env bash
# Creates or updates the training virtualenv OUTSIDE the repository and prints its python path on stdout
# (progress goes to stderr), e.g.  PY="$(bash policies/train/setup_venv.sh)"
#
#   venv:      ${AIRROADS_CACHE:-$HOME/.cache/airroads}/venv
#   pip cache: ${AIRROADS_CACHE:-$HOME/.cache/airroads}/pip
#   python:    $AIRROADS_PYTHON, else python3.11, else python3
#
# Idempotent and fast once installed: the sha256 of requirements.txt is stored in a stamp file inside the
# venv, and pip runs only when the stamp is missing or differs.
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cache="${AIRROADS_CACHE:-$HOME/.cache/airroads}"
venv="$cache/venv"
req="$here/requirements.txt"
stamp="$venv/.requirements.sha256"
want="$(sha256sum "$req" | cut -d' ' -f1)"

if [[ -x "$venv/bin/python" && -f "$stamp" && "$(cat "$stamp")" == "$want" ]]; then
    echo "$venv/bin/python"
    exit 0
fi

base="${AIRROADS_PYTHON:-$(command -v python3.11 || command -v python3)}"
mkdir -p "$cache"
if [[ ! -x "$venv/bin/python" ]]; then
    echo "setup_venv: creating $venv with $base" >&2
    "$base" -m venv "$venv"
fi
echo "setup_venv: installing $req (the first time downloads ~3 GB)" >&2
"$venv/bin/python" -m pip install --disable-pip-version-check --cache-dir "$cache/pip" -r "$req" >&2
echo "$want" >"$stamp"
echo "$venv/bin/python"
