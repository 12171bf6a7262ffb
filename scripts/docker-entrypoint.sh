#!/bin/sh
# Container entrypoint: on the first `serve` against a database without tokens, create an
# admin token, keep its secret in a file only the service's user can read (never in the
# log), and say how to use it; then run mocapstore.
set -eu
secret_file="${MOCAP_ADMIN_TOKEN_FILE:-/data/admin-token}"
if [ "${1:-}" = "serve" ]; then
    umask 077
    created=$(mocapstore token create --first --scope admin --name "${MOCAP_ADMIN_TOKEN_NAME:-admin}")
    if [ -n "$created" ]; then
        printf '%s\n' "$created" | sed -n 's/^secret, shown this once: //p' > "$secret_file"
        echo "mocapstore: first start, so an admin token was created; its secret is in $secret_file."
        echo "  read it:   docker compose exec mocapstore cat $secret_file"
        echo "  use it:    curl -H \"Authorization: Bearer \$(cat admin-token)\" http://localhost:8080/v1/takes"
        echo "  CLI:       MOCAP_TOKEN=\$(cat admin-token) mocapstore ingest --server http://localhost:8080 FOLDER"
        echo "  more:      docker compose exec mocapstore mocapstore token create --scope read --name NAME"
    fi
fi
exec mocapstore "$@"
