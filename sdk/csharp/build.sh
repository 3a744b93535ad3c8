#!/usr/bin/env bash
# Builds the C# SDK with Mono's compiler (Debian: apt-get install mono-mcs
# libmono-system-net-http4.0-cil) and runs its tests:
#   sdk/csharp/build.sh          build/QuadLoc.Client.dll and build/QuadLoc.Client.Tests.exe
#   sdk/csharp/build.sh test     ... then run the tests (live ones need QUADLOC_URL, see tests/)
# C# 7.2 (what mcs speaks, and Unity too); the library uses .NET Standard 2.0 APIs only.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
mkdir -p "$here/build"
mcs -langversion:7.2 -target:library -nowarn:1591 -warnaserror+ -r:System.Net.Http.dll \
    -doc:"$here/build/QuadLoc.Client.xml" -out:"$here/build/QuadLoc.Client.dll" "$here"/QuadLoc.Client/*.cs
mcs -langversion:7.2 -nowarn:1591 -r:System.Net.Http.dll -r:"$here/build/QuadLoc.Client.dll" \
    -out:"$here/build/QuadLoc.Client.Tests.exe" "$here"/tests/*.cs
if [ "${1:-}" = "test" ]; then
  exec mono "$here/build/QuadLoc.Client.Tests.exe"
fi
