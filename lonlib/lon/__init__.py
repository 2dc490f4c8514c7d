"""Local Optima Networks: the three graphs (LON, MLON, CMLON), the field's metrics, file
formats, and the behavioural LON."""
