from sb3_denfac.cacla.cacla import CACLA
from sb3_denfac.cacla.policies import CACLAPolicy, MlpPolicy

__all__ = ["CACLA", "CACLAPolicy", "MlpPolicy"]
