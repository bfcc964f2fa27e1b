#!/bin/sh
# Certificates for zenoh with mutual TLS (docs/zenoh/*.json5), made with the openssl CLI.
#
#   sh docs/zenoh/make-certs.sh DIR [SERVICE_NAME ...]
#
# In DIR: ca.pem/ca.key (the certificate authority; made once, kept if already there),
# service.pem/service.key (CN uavmec-service, the service's identity), user.pem/user.key
# (CN uavmec-user, the identity every user presents). SERVICE_NAME: the DNS names or IP
# addresses users connect to, written into the service certificate, which users check
# (default: localhost 127.0.0.1). The access control rules match these common names.
#
#   sh docs/zenoh/make-certs.sh DIR --user NAME
#
# adds NAME.pem/NAME.key, another user certificate (CN uavmec-user) signed by DIR's CA, for a
# user of its own (one per device: a lost device's certificate is just not renewed).
#
#   sh docs/zenoh/make-certs.sh DIR --operator NAME
#
# adds NAME.pem/NAME.key, another operator certificate (CN uavmec-operator): the identity that
# may send the service its operator commands (start, hold, status); the first run makes
# operator.pem/operator.key. Give it to the operator's ground station only, never to users.
#
# Keep ca.key off the aircraft and off users' devices: whoever holds it can make identities.
set -eu
[ $# -ge 1 ] || { echo "usage: $0 DIR [SERVICE_NAME ...] | $0 DIR --user NAME | $0 DIR --operator NAME" >&2; exit 2; }
dir=$1; shift
mkdir -p "$dir"
umask 077
days=825

if [ ! -f "$dir/ca.key" ]; then
    openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 3650 \
        -keyout "$dir/ca.key" -out "$dir/ca.pem" -subj "/CN=uavmec-ca" \
        -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" 2>/dev/null
fi

# sign NAME CN EXTENSIONS: NAME.key (PKCS#8, as zenoh reads it) and NAME.pem signed by the CA
sign() {
    openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes \
        -keyout "$dir/$1.key" -out "$dir/$1.csr" -subj "/CN=$2" 2>/dev/null
    printf '%s\n' "basicConstraints=CA:FALSE" "keyUsage=critical,digitalSignature" "$3" > "$dir/$1.ext"
    openssl x509 -req -in "$dir/$1.csr" -CA "$dir/ca.pem" -CAkey "$dir/ca.key" -CAcreateserial \
        -days $days -extfile "$dir/$1.ext" -out "$dir/$1.pem" 2>/dev/null
    rm -f "$dir/$1.csr" "$dir/$1.ext"
    echo "$dir/$1.pem: CN=$2"
}

if [ "${1:-}" = "--user" ]; then
    [ $# -eq 2 ] || { echo "usage: $0 DIR --user NAME" >&2; exit 2; }
    sign "$2" uavmec-user "extendedKeyUsage=clientAuth"
    exit 0
fi

if [ "${1:-}" = "--operator" ]; then
    [ $# -eq 2 ] || { echo "usage: $0 DIR --operator NAME" >&2; exit 2; }
    sign "$2" uavmec-operator "extendedKeyUsage=clientAuth"
    exit 0
fi

[ $# -ge 1 ] || set -- localhost 127.0.0.1
san=""
for name in "$@"; do
    case $name in
        *[!0-9.]*) entry="DNS:$name" ;;  # not only digits and dots: a host name
        *) entry="IP:$name" ;;
    esac
    san="${san:+$san,}$entry"
done
# the service both accepts users (server) and may connect to a router (client)
sign service uavmec-service "extendedKeyUsage=serverAuth,clientAuth
subjectAltName=$san"
sign user uavmec-user "extendedKeyUsage=clientAuth"
sign operator uavmec-operator "extendedKeyUsage=clientAuth"
