"""Bags in the rosbag2 MCAP layout: one writer, one reader, a recorder node and a player.

>>> from cdpr_tools.bag import BagWriter, BagReader
"""
from cdpr_tools.bag.reader import BagMessage, BagReader, TopicInfo
from cdpr_tools.bag.writer import BagWriter

__all__ = ["BagMessage", "BagReader", "BagWriter", "TopicInfo"]
