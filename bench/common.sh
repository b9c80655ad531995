# Sourced by the comparison scripts with their arguments (`source bench/common.sh "$@"`): makes
# the Snell binaries given absolute (target/release/snell, brought up to date, where none is
# given) into `bins`, moves to the repository's root, and sets SCENES to the shared test data
# (SNELL_SCENES, default ../shared/scenes beside the checkout).
set -euo pipefail
bins=()
for b in "$@"; do bins+=("$(readlink -f "$b")"); done
cd "$(dirname "${BASH_SOURCE[0]}")/.."
if [ ${#bins[@]} -eq 0 ]; then
    # Built every time (a no-op when up to date), so that an edit is never measured stale.
    cargo build --release -q
    bins=("$PWD/target/release/snell")
fi
SCENES="${SNELL_SCENES:-$(cd .. && pwd)/shared/scenes}"
