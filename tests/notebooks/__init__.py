"""The notebooks under papermill and in JupyterLab, and lonlib.notebook_run (papermill's engine)."""
