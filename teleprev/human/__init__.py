"""The human side: SMPL-X as the common representation of what the operator's body and hands do."""
