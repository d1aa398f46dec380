#!/usr/bin/env bash
# Fails when a function defined in core/, calib/ or pipeline/ runs over 120 lines (its body,
# from the line after its opening brace to its closing one): a longer one is a run of steps
# that want names of their own, each readable and testable alone. Tests are not counted.
# Functions are found as the house writes them (clang-format, Google style): a definition
# begins at column 0 and its body ends at the first "}" at column 0.
#   scripts/check-function-length.sh [--list N]   also list every function over N lines
set -euo pipefail
cd "$(dirname "$0")/.."
python3 - "$@" <<'PY'
import re, subprocess, sys

LIMIT = 120
list_over = int(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[1] == '--list' else None
files = subprocess.run(['git', 'ls-files', 'core/*.cc', 'calib/*.cc', 'pipeline/*.cc',
                        'core/*.h', 'calib/*.h', 'pipeline/*.h'],
                       capture_output=True, text=True, check=True).stdout.split()
not_function = re.compile(r'^(namespace|struct|class|enum|union|extern|template|typedef|using|#|//|\})')
found, over = 0, []
for path in files:
    if path.endswith('_test.cc'):
        continue
    lines = open(path, encoding='utf-8').read().split('\n')
    k = 0
    while k < len(lines):
        line = lines[k]
        if not line or line[0].isspace() or not_function.match(line):
            k += 1
            continue
        # A signature at column 0, perhaps over several lines, up to the line ending in "{".
        start = k
        def ends(text):  # The signature's end: its body's brace, a declaration, a one-liner.
            text = text.rstrip()
            return text.endswith('{') or text.endswith(';') or text.endswith('}')
        while k < len(lines) and not ends(lines[k]):
            k += 1
        if k >= len(lines) or not lines[k].rstrip().endswith('{') or \
                '=' in lines[start].split('(')[0]:
            k += 1
            continue
        body_start = k + 1
        end = body_start
        while end < len(lines) and not lines[end].startswith('}'):
            end += 1
        length = end - body_start
        name = re.sub(r'\(.*', '', lines[start]).split()[-1] if '(' in lines[start] else lines[start]
        found += 1
        if length > LIMIT or (list_over is not None and length > list_over):
            over.append((length, f'{path}:{start + 1}: {name} is {length} lines'))
        k = end + 1
for length, text in sorted(over, reverse=True):
    print(text)
too_long = [t for length, t in over if length > LIMIT]
if too_long:
    print(f'function-length: {len(too_long)} function(s) over {LIMIT} lines: name their steps')
    sys.exit(1)
print(f'function-length: {found} functions in core/, calib/ and pipeline/, none over {LIMIT} lines')
PY
