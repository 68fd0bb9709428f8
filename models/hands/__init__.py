"""Robot hands: `load_hand(name_or_path)` gives a HandModel built from URDF + hand.json."""

from models.hands.meta import Fingertip, HandMeta, Palm
from models.hands.model import HandModel, available_hands, load_hand

__all__ = ["Fingertip", "HandMeta", "HandModel", "Palm", "available_hands", "load_hand"]
