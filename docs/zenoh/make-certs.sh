#!/bin/sh
# Certificates for zenoh with mutual TLS (docs/zenoh/*.json5), made with the openssl CLI.
#
#   sh docs/zenoh/make-certs.sh DIR [SERVICE_NAME ...]
#
# In DIR: ca.pem/ca.key (the certificate authority; made once, kept if already there) and
# service.pem/service.key (CN uavmec-service, the service's identity). SERVICE_NAME: the DNS
# names or IP addresses users connect to, written into the service certificate, which users
# check (default: localhost 127.0.0.1).
#
#   sh docs/zenoh/make-certs.sh DIR --user USER_ID
#
# adds USER_ID.pem/USER_ID.key, a user's certificate signed by DIR's CA whose common name is
# its user id (1-64 of A-Z a-z 0-9 _ . : -): the service's access control lets that
# certificate submit requests as USER_ID only, on its own request key, and follow its own
# place. It prints the entries to add to the access_control of service-tls-acl.json5 (for
# prefix uavmec and vehicle uav1: change them with yours), one line each for "rules",
# "subjects" and "policies". One certificate per user and device: a lost device's
# certificate is just not renewed, and its entries removed.
#
#   sh docs/zenoh/make-certs.sh DIR --vehicle VEHICLE
#
# adds VEHICLE.pem/VEHICLE.key, a fleet UAV's certificate (CN uavmec-vehicle-VEHICLE) for its
# service's connection to the ground routers (docs/zenoh/vehicle-tls.json5), and prints the
# entries to add to fleet-router-tls-acl.json5: that certificate may speak for VEHICLE only.
#
#   sh docs/zenoh/make-certs.sh DIR --operator NAME
#
# adds NAME.pem/NAME.key, another operator certificate (CN uavmec-operator): the identity that
# may send the service its operator commands (start, hold, status); the first run makes
# operator.pem/operator.key. Give it to the operator's ground station only, never to users.
#
# Keep ca.key off the aircraft and off users' devices: whoever holds it can make identities.
set -eu
[ $# -ge 1 ] || { echo "usage: $0 DIR [SERVICE_NAME ...] | $0 DIR --user NAME | $0 DIR --vehicle VEHICLE | $0 DIR --operator NAME" >&2; exit 2; }
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

# check_id KIND VALUE: 1-64 of A-Z a-z 0-9 _ . : - (a key chunk with no wildcard), or exit 2
check_id() {
    case $2 in
        ''|*[!A-Za-z0-9_.:-]*) echo "$0: '$2' is not a $1 id (1-64 of A-Z a-z 0-9 _ . : -)" >&2; exit 2 ;;
    esac
    [ ${#2} -le 64 ] || { echo "$0: '$2' is longer than 64 characters" >&2; exit 2; }
}

if [ "${1:-}" = "--user" ]; then
    [ $# -eq 2 ] || { echo "usage: $0 DIR --user USER_ID" >&2; exit 2; }
    user=$2
    # the common name is the user id the access control binds: nothing else may pass
    check_id user "$user"
    case $user in
        uavmec-*|service|ca|operator)
            echo "$0: $user is reserved (uavmec-...: the names of the service, the CA, the operator and the vehicles)" >&2; exit 2 ;;
    esac
    sign "$user" "$user" "extendedKeyUsage=clientAuth"
    k="uavmec/uav1"
    echo "add to the access_control of service-tls-acl.json5 (prefix uavmec, vehicle uav1: change them with yours):"
    echo "rules: { id: \"$user-in\", permission: \"allow\", flows: [\"ingress\"], messages: [\"query\", \"declare_subscriber\"], key_exprs: [\"$k/request/$user\", \"$k/users/$user\", \"uavmec/fleet/request/$user\"] }, { id: \"$user-out\", permission: \"allow\", flows: [\"egress\"], messages: [\"reply\", \"put\"], key_exprs: [\"$k/request/$user\", \"$k/users/$user\", \"uavmec/fleet/request/$user\"] },"
    echo "subjects: { id: \"$user\", cert_common_names: [\"$user\"] },"
    echo "policies: { id: \"$user\", rules: [\"user-asks\", \"user-follows\", \"user-checks-alive\", \"to-users\", \"queryables-known\", \"$user-in\", \"$user-out\"], subjects: [\"$user\"] },"
    echo "in fleet-router-tls-acl.json5 the same subject and policy, with these rules (its place on every member's key):"
    echo "fleet rules: { id: \"$user-in\", permission: \"allow\", flows: [\"ingress\"], messages: [\"query\", \"declare_subscriber\"], key_exprs: [\"$k/request/$user\", \"uavmec/*/users/$user\", \"uavmec/fleet/request/$user\"] }, { id: \"$user-out\", permission: \"allow\", flows: [\"egress\"], messages: [\"reply\", \"put\"], key_exprs: [\"$k/request/$user\", \"uavmec/*/users/$user\", \"uavmec/fleet/request/$user\"] },"
    exit 0
fi

if [ "${1:-}" = "--vehicle" ]; then
    [ $# -eq 2 ] || { echo "usage: $0 DIR --vehicle VEHICLE" >&2; exit 2; }
    v=$2
    # the vehicle id as the service's keys take it (protocol/keys.py): no wildcards, no "fleet"
    check_id vehicle "$v"
    [ "$v" != fleet ] || { echo "$0: no vehicle may be named fleet (the fleet's keys)" >&2; exit 2; }
    sign "$v" "uavmec-vehicle-$v" "extendedKeyUsage=clientAuth"
    k="uavmec"
    echo "add to the access_control of fleet-router-tls-acl.json5 (prefix uavmec: change it with yours):"
    echo "rules: { id: \"$v-speaks\", permission: \"allow\", flows: [\"ingress\"], messages: [\"put\", \"delete\", \"declare_queryable\", \"reply\", \"liveliness_token\"], key_exprs: [\"$k/$v/**\", \"$k/fleet/members/$v\", \"$k/fleet/uavs/$v\", \"$k/fleet/uavs/$v/@adv/**\", \"$k/fleet/intentions/$v\", \"$k/fleet/intentions/$v/@adv/**\", \"$k/fleet/served/$v\", \"$k/fleet/served/$v/@adv/**\", \"$k/fleet/positions/$v\", \"$k/fleet/statuses/$v\"] }, { id: \"$v-asked\", permission: \"allow\", flows: [\"egress\"], messages: [\"query\", \"declare_subscriber\"], key_exprs: [\"$k/$v/**\", \"$k/fleet/uavs/$v\", \"$k/fleet/uavs/$v/@adv/**\", \"$k/fleet/intentions/$v\", \"$k/fleet/intentions/$v/@adv/**\", \"$k/fleet/served/$v\", \"$k/fleet/served/$v/@adv/**\"] },"
    echo "subjects: { id: \"$v\", cert_common_names: [\"uavmec-vehicle-$v\"] },"
    echo "policies: { id: \"$v\", rules: [\"fleet-follows\", \"to-fleet\", \"fleet-serves\", \"fleet-asked\", \"$v-speaks\", \"$v-asked\"], subjects: [\"$v\"] },"
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
sign operator uavmec-operator "extendedKeyUsage=clientAuth"
echo "users: sh $0 $dir --user USER_ID (one certificate per user id)"
