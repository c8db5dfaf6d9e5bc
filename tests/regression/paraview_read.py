"""Run by pvpython (harness.paraview_frames): reads a softbody .xdmf with
ParaView's Xdmf3 reader and saves, per time step, the points, the "velocity"
point field and the number of cells into an .npz file.

    pvpython --force-offscreen-rendering paraview_read.py RESULT.xdmf OUT.npz
"""
import sys

import numpy as np
from paraview import simple
from vtkmodules.numpy_interface import dataset_adapter

xdmf, out = sys.argv[1], sys.argv[2]
reader = simple.Xdmf3ReaderS(FileName=[xdmf])
reader.UpdatePipelineInformation()
steps = reader.TimestepValues
times = list(steps) if hasattr(steps, "__len__") else [steps]
positions, velocities, cells = [], [], []
for t in times:
    reader.UpdatePipeline(t)  # in pvpython's built-in session the reader's output is local
    data = reader.GetClientSideObject().GetOutputDataObject(0)
    if data.IsA("vtkMultiBlockDataSet"):
        data = data.GetBlock(0)
    wrapped = dataset_adapter.WrapDataObject(data)
    positions.append(np.array(wrapped.Points, copy=True))  # VTK reuses the memory
    velocities.append(np.array(wrapped.PointData["velocity"], copy=True))
    cells.append(data.GetNumberOfCells())
np.savez(out, times=np.array(times), positions=np.array(positions), velocities=np.array(velocities),
         cells=np.array(cells))
