#!/bin/sh
# Print the path of a Python >= 3.12, looking at $PYTHON, python3.13, python3.12,
# python3, then the oldest pyenv version that is >= 3.12 (the one the wheel is built for). Exit 1 with advice when there is none.
ok() { "$1" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 12) else 1)' 2>/dev/null; }
for c in "${PYTHON:-}" python3.13 python3.12 python3; do
  [ -n "$c" ] || continue
  p=$(command -v "$c" 2>/dev/null) || continue
  if ok "$p"; then echo "$p"; exit 0; fi
done
if command -v pyenv >/dev/null 2>&1 || [ -d "${PYENV_ROOT:-$HOME/.pyenv}" ]; then
  root=${PYENV_ROOT:-$HOME/.pyenv}
  for v in $(ls -1 "$root/versions" 2>/dev/null | sort -V); do
    p="$root/versions/$v/bin/python"
    if [ -x "$p" ] && ok "$p"; then echo "$p"; exit 0; fi
  done
fi
echo "eyemech needs Python >= 3.12 (the DOLFINx wheel does not support older ones)." >&2
echo "Install one (e.g. 'pyenv install 3.12', or your OS package python3.12) or set PYTHON=/path/to/python3.12." >&2
exit 1
