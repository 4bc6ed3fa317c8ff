"""Machine-learning dispatch (thesis case study III): training data, linear SVM models, CLI."""

from softplc.svm.dataset import Dataset, DatasetError, feature_names, generate, read_dataset
from softplc.svm.model import ModelError, TaskModel, train

__all__ = ["Dataset", "DatasetError", "ModelError", "TaskModel", "feature_names", "generate", "read_dataset", "train"]
