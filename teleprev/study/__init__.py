"""User studies (TelePreview appendix D-F): questionnaire, practice time, and the paper's tables."""
