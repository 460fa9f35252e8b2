"""Developmental programs: which learner, goal, trace metric and detector, per world kind."""

from sensorimotor.agent.programs.base import Decision, EchoProgram, EmbeddingOutput, EventOutput, Program
from sensorimotor.agent.programs.registry import PROGRAMS, make_program

__all__ = ["Decision", "EchoProgram", "EmbeddingOutput", "EventOutput", "Program", "PROGRAMS", "make_program"]
