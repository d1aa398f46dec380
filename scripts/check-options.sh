#!/usr/bin/env bash
# Fails when a struct named *Options in the sources has no Check(std::string* why) const: every
# set of options says what it cannot use, by name, before it is used.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 - <<'PY'
import re, subprocess, sys

files = subprocess.run(['git', 'ls-files', '*.h'], capture_output=True, text=True,
                       check=True).stdout.split()
missing = []
for path in files:
    text = open(path, encoding='utf-8').read()
    for m in re.finditer(r'^struct (\w+Options) \{\n(.*?)^\};', text, re.S | re.M):
        if not re.search(r'\bbool Check\(std::string\* why\) const;', m.group(2)):
            missing.append(f'{path}: {m.group(1)} has no Check(std::string* why) const')
for line in missing:
    print(line)
if missing:
    sys.exit(1)
print(f'options: every *Options struct in {len(files)} headers has Check()')
PY
