#!/bin/sh
# Print the path of the newest Python interpreter >= 3.12.
# Order of search (the README contract): $PYTHON if set; else interpreters on the PATH;
# else interpreters installed under pyenv ($PYENV_ROOT or ~/.pyenv), which on our
# machines are off the PATH. Exits 1 with a clear message when there is none.
set -u

version_key() {  # prints e.g. 313 for Python 3.13, nothing if $1 is not a usable Python
    "$1" -c 'import sys; print(sys.version_info[0] * 100 + sys.version_info[1])' 2>/dev/null
}

if [ -n "${PYTHON:-}" ]; then
    key=$(version_key "$PYTHON")
    if [ -n "$key" ] && [ "$key" -ge 312 ]; then
        command -v "$PYTHON" 2>/dev/null || echo "$PYTHON"
        exit 0
    fi
    echo "error: PYTHON=$PYTHON is not a working Python 3.12 or newer" >&2
    exit 1
fi

best=""; best_key=0
consider() {
    key=$(version_key "$1")
    if [ -n "$key" ] && [ "$key" -ge 312 ] && [ "$key" -gt "$best_key" ]; then
        best=$1; best_key=$key
    fi
}

for minor in 20 19 18 17 16 15 14 13 12; do
    p=$(command -v "python3.$minor" 2>/dev/null) && consider "$p"
done
for name in python3 python; do
    p=$(command -v "$name" 2>/dev/null) && consider "$p"
done

if [ -z "$best" ]; then
    root=${PYENV_ROOT:-$HOME/.pyenv}
    for p in "$root"/versions/*/bin/python3; do
        [ -x "$p" ] && consider "$p"
    done
fi

if [ -z "$best" ]; then
    echo "error: pamid needs Python 3.12 or newer (current JAX and ArviZ require it)." >&2
    echo "       None was found on the PATH or under pyenv (${PYENV_ROOT:-$HOME/.pyenv}/versions)." >&2
    echo "       Install one, or point PYTHON at it: make test PYTHON=/path/to/python3.12" >&2
    exit 1
fi
echo "$best"
