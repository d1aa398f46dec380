#!/usr/bin/env bash
# Fails when the docs name a path in the repository that does not exist: every `code span` in
# README.md, docs/*.md and the folders' README.md whose first part is a top-level folder of the
# repository (core/decode/decode.h, tests/data/, scripts/demo.sh), and every relative link
# target ([page](docs/operator.md)). Paths on a station (/etc/vellum/...), in a results folder
# (raw/, results/) or with placeholders (<id>, ...) are not the repository's and are skipped; a
# glob (io/calibration_io.*) must match a file.
set -euo pipefail
cd "$(dirname "$0")/.."
python3 - "$@" <<'EOF'
import glob, os, re, subprocess, sys

try:
    files = subprocess.run(['git', 'ls-files'], capture_output=True, text=True,
                           check=True).stdout.split()
except (OSError, subprocess.CalledProcessError):
    files = [os.path.relpath(os.path.join(d, f)) for d, _, fs in os.walk('.') for f in fs]
top = {f.split('/')[0] for f in files if '/' in f}
docs = ['README.md'] + sorted(f for f in files if f.endswith('.md') and
                              (f.startswith('docs/') or f.count('/') == 1))
bad = 0
checked = 0

def exists(path):
    # A file, a folder, a glob (core/io/calibration_io.*), or a program by its source's name
    # (fuzz/fuzz_files for fuzz/fuzz_files.cc).
    return os.path.exists(path) or bool(glob.glob(path)) or bool(glob.glob(path + '.*'))

for doc in docs:
    if not exists(doc):
        continue
    text = open(doc, encoding='utf-8').read()
    here = os.path.dirname(doc)
    names = []
    for span in re.findall(r'`([^`\n]+)`', text):
        token = span.strip().split()[0] if span.strip() else ''
        if '/' not in token or token.split('/')[0] not in top:
            continue
        names.append((token, token))
    for target in re.findall(r'\]\(([^)\s]+)\)', text):
        if re.match(r'[a-z]+:', target) or target.startswith('#'):
            continue
        names.append((target, os.path.normpath(os.path.join(here, target))))
    for shown, path in names:
        path = re.sub(r'#.*$', '', path)
        path = re.sub(r':[0-9]+$', '', path).rstrip('.,;:)')
        if re.search(r'[<>{}$]|\.\.\.|NNN', path) or not path:
            continue
        checked += 1
        if not exists(path):
            print(f'check-docs: {doc} names {shown}, which is not in the repository')
            bad = 1
print(f'check-docs: {checked} paths named in {len(docs)} pages, every one there' if not bad
      else 'check-docs: mend the names above (or the files)')
sys.exit(bad)
EOF
