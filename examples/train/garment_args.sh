# Sourced by data_amc.sh, data_arms.sh and data_cap35.sh with their arguments GARMENT OUT [BASE]:
# sets those three (BASE: scratch/rest by default) and LAST, the regressor set whose copy a
# capture set is projected onto (v4cs for the T-shirt, v4css for the dress).
NAME=$(basename "$0")
GARMENT=${1:?usage: $NAME tshirt|dress OUT [BASE]}
OUT=${2:?usage: $NAME tshirt|dress OUT [BASE]}
BASE=${3:-scratch/rest}
case $GARMENT in
    tshirt) LAST=v4cs ;;
    dress) LAST=v4css ;;
    *) echo "$NAME: the garment is tshirt or dress, not '$GARMENT'" >&2; exit 2 ;;
esac
