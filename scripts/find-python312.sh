#!/usr/bin/env bash
# Print the path of a working Python 3.12 interpreter: PATH first, then pyenv.
for c in "$(command -v python3.12 2>/dev/null)" \
         "$(command -v pyenv >/dev/null 2>&1 && pyenv root 2>/dev/null)"/versions/3.12*/bin/python3.12 \
         "${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.12*/bin/python3.12; do
  if [ -n "$c" ] && [ -x "$c" ] && "$c" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 12))' 2>/dev/null; then
    echo "$c"; exit 0
  fi
done
echo "error: Python 3.12 not found on PATH or through pyenv" >&2
exit 1
