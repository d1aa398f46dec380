#!/usr/bin/env bash
# Serves a folder of restored scans over IIIF: lighttpd (Debian `lighttpd`) serves DIR's files
# (the manifests `vellum iiif` writes) and hands /iiif/... to IIPImage (Debian
# `iipimage-server`, FastCGI), which serves every restored_pyramid.tif under DIR through the
# IIIF Image API, its identifier the file's path under DIR with '/' as %2F.
#   scripts/serve-iiif.sh DIR [PORT] [ADDRESS]
# PORT defaults to 8080, ADDRESS to 127.0.0.1 (this machine only; give 0.0.0.0 to serve the
# reading room). Runs in the foreground until stopped; its logs go to a temporary folder, named
# on start (or VELLUM_IIIF_WORK). Then: vellum iiif --root DIR --base http://ADDRESS:PORT RESULTS...
set -euo pipefail
if [ $# -lt 1 ] || [ "$1" = "--help" ] || [ "$1" = "-h" ]; then
  sed -n '2,10p' "$0" | sed 's/^# \{0,1\}//'
  [ $# -ge 1 ] && exit 0 || exit 2
fi
root=$(realpath "$1")
port=${2:-8080}
address=${3:-127.0.0.1}
iipsrv=/usr/lib/iipimage-server/iipsrv.fcgi
[ -d "$root" ] || { echo "serve-iiif: $1: no such folder" >&2; exit 1; }
[ -x "$iipsrv" ] || { echo "serve-iiif: $iipsrv missing (apt install iipimage-server)" >&2; exit 1; }
command -v lighttpd >/dev/null || { echo "serve-iiif: lighttpd missing (apt install lighttpd)" >&2; exit 1; }
work=${VELLUM_IIIF_WORK:-$(mktemp -d /tmp/vellum-iiif.XXXXXX)}
mkdir -p "$work"
cat >"$work/lighttpd.conf" <<CONF
server.document-root = "$root"
server.bind = "$address"
server.port = $port
server.errorlog = "$work/lighttpd.log"
server.pid-file = "$work/lighttpd.pid"
server.modules = ( "mod_rewrite", "mod_fastcgi", "mod_setenv" )
mimetype.assign = ( ".json" => "application/json", ".html" => "text/html", ".png" => "image/png",
                    ".jpg" => "image/jpeg", ".tif" => "image/tiff", ".txt" => "text/plain" )
setenv.add-response-header = ( "Access-Control-Allow-Origin" => "*" )
url.rewrite-once = ( "^/iiif/(.*)\$" => "/fcgi-bin/iipsrv.fcgi?IIIF=\$1" )
fastcgi.server = ( "/fcgi-bin/iipsrv.fcgi" => ((
  "socket" => "$work/iipsrv.socket",
  "bin-path" => "$iipsrv",
  "check-local" => "disable",
  "min-procs" => 1,
  "max-procs" => 1,
  "bin-environment" => (
    "FILESYSTEM_PREFIX" => "$root/",
    "LOGFILE" => "$work/iipsrv.log",
    "VERBOSITY" => "2",
    "MAX_IMAGE_CACHE_SIZE" => "64",
    "JPEG_QUALITY" => "90",
    "CORS" => "*"
  )
)))
CONF
echo "serve-iiif: http://$address:$port/ serves $root (IIIF images at /iiif/); logs in $work" >&2
exec lighttpd -D -f "$work/lighttpd.conf"
